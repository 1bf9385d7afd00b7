"""The ground-truth surface as a LiDAR beside the left camera sees it.

A LiDAR mounted away from the left camera sees past foreground edges where the
camera cannot. To simulate its returns from a frame's ground truth (the
surface the *camera* sees), :func:`render_lidar_depth` builds a z-buffer of the
scene from the LiDAR's viewpoint:

1. **Surface samples.** Every valid ground-truth pixel is back-projected with
   the frame's geometry (``Z = f b / (d + doffs)``, ``X = (u - cx) Z / f``,
   ``Y = (v - cy) Z / f``).
2. **Hidden background.** The LiDAR sees background the camera does not: the
   part hidden behind a foreground edge. The ground truth has no sample there,
   so behind every pixel whose window holds a *clearly farther* pixel
   (disparity below ``(1 - HIDDEN_MARGIN)`` times its own) a second sample is
   added at the farthest disparity of that window: the background continued
   behind the foreground edge. The window's radius is the largest parallax
   the offset can cause in the scene (:func:`parallax_bound`), so every
   background a LiDAR can see past an edge is covered.
3. **Z-buffer.** The samples are moved into the LiDAR frame
   (``P_l = R^T (P_c - t)``) and projected with the left camera's intrinsics
   (a virtual pinhole image at the LiDAR's origin, same size as the left
   image); each sample covers the 2 x 2 pixels around its position, so a
   surface seen from a slightly different angle has no cracks; the nearest
   depth wins each pixel. Samples a nearer surface hides from the LiDAR
   disappear here; hidden background the LiDAR sees past an edge survives.

:class:`~vpp_service.sources.sensors.LidarSensor` samples its beams in this
image and projects the returns into the left camera, where the ones from the
hidden background land on foreground pixels: see-through points.
"""

from __future__ import annotations

import math

import numpy as np

#: A window pixel is "clearly farther" below this fraction of the disparity (hidden background, step 2).
HIDDEN_MARGIN = 0.05
#: Largest radius (px) of the hidden-background window.
MAX_HIDDEN_RADIUS = 128


def rotation_matrix(degrees: tuple[float, float, float]) -> np.ndarray:
    """``Rz @ Ry @ Rx`` of rotations (degrees) about the camera's x, y and z axes."""
    rx, ry, rz = (math.radians(a) for a in degrees)
    cx, sx, cy, sy, cz, sz = math.cos(rx), math.sin(rx), math.cos(ry), math.sin(ry), math.cos(rz), math.sin(rz)
    mx = np.array([[1.0, 0.0, 0.0], [0.0, cx, -sx], [0.0, sx, cx]])
    my = np.array([[cy, 0.0, sy], [0.0, 1.0, 0.0], [-sy, 0.0, cy]])
    mz = np.array([[cz, -sz, 0.0], [sz, cz, 0.0], [0.0, 0.0, 1.0]])
    return mz @ my @ mx


def _window_min_1d(a: np.ndarray, radius: int, axis: int) -> np.ndarray:
    """Minimum over ``[i - radius, i + radius]`` along ``axis`` (+inf beyond the border), by doubling."""
    m = np.moveaxis(a, axis, -1)
    n, w = m.shape[-1], 2 * radius + 1
    pad = np.full((*m.shape[:-1], radius), np.inf, a.dtype)
    m = np.concatenate([pad, m, pad], axis=-1)
    have = 1
    while 2 * have <= w:
        m = np.minimum(m[..., :-have], m[..., have:])
        have *= 2
    out = np.minimum(m[..., :n], m[..., w - have : w - have + n])
    return np.moveaxis(out, -1, axis)


def window_min(a: np.ndarray, radius: int) -> np.ndarray:
    """Minimum of ``a`` over the ``(2 radius + 1)``-square window around each pixel (NaN ignored)."""
    src = np.where(np.isnan(a), np.inf, a)
    return _window_min_1d(_window_min_1d(src, radius, 0), radius, 1)


def parallax_bound(
    gt: np.ndarray, translation: np.ndarray, *, f: float, b: float, doffs: float, cx: float, cy: float
) -> float:
    """Largest shift (px) between the camera's and the LiDAR's views of the nearest vs. an infinitely far point.

    ``f |t_xy| / Z_min + r_max |t_z| / Z_min``, with ``Z_min`` the nearest
    ground-truth depth and ``r_max`` the largest distance of a pixel from the
    principal point.
    """
    h, w = gt.shape
    valid = gt[np.isfinite(gt)]
    if valid.size == 0:
        return 0.0
    inv_z = (float(valid.max()) + doffs) / (f * b)
    r_max = math.hypot(max(cx, w - 1 - cx), max(cy, h - 1 - cy))
    t = np.asarray(translation, np.float64)
    return float(inv_z * (f * math.hypot(t[0], t[1]) + r_max * abs(t[2])))


def surface_samples(gt: np.ndarray, radius: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rows, columns and disparities of the ground truth plus the hidden background behind its edges (step 2)."""
    rows, cols = np.nonzero(np.isfinite(gt))
    d = gt[rows, cols]
    if radius > 0 and rows.size:
        far = window_min(gt, radius)[rows, cols]
        hidden = far < d * (1.0 - HIDDEN_MARGIN)
        rows = np.concatenate([rows, rows[hidden]])
        cols = np.concatenate([cols, cols[hidden]])
        d = np.concatenate([d, far[hidden]])
    return rows, cols, d.astype(np.float64)


def render_lidar_depth(
    gt: np.ndarray,
    rotation: np.ndarray,
    translation: np.ndarray,
    *,
    f: float,
    b: float,
    doffs: float,
    cx: float,
    cy: float,
) -> np.ndarray:
    """Z-buffer of the ground-truth surface seen from the LiDAR (see the module docs).

    Parameters
    ----------
    gt : ndarray
        H x W ground-truth disparity of the left view, NaN = invalid.
    rotation : ndarray
        3 x 3 rotation from the LiDAR frame to the left camera frame.
    translation : ndarray
        The LiDAR origin in the left camera frame (metres; x right, y down, z forward).
    f, b, doffs, cx, cy : float
        Geometry of the frame (focal length px, baseline m, doffs px, principal point px).

    Returns
    -------
    ndarray
        H x W float64 depth along the LiDAR's z axis (metres) of the nearest
        surface at each pixel of the LiDAR's virtual image; +inf = no surface.
    """
    h, w = gt.shape
    radius = min(MAX_HIDDEN_RADIUS, math.ceil(parallax_bound(gt, translation, f=f, b=b, doffs=doffs, cx=cx, cy=cy)) + 2)
    rows, cols, d = surface_samples(gt, radius)
    z = f * b / (d + doffs)
    pc = np.stack([(cols - cx) * z / f, (rows - cy) * z / f, z])
    pl = rotation.T @ (pc - np.asarray(translation, np.float64).reshape(3, 1))
    zl = pl[2]
    front = zl > 0
    pl, zl = pl[:, front], zl[front]
    u = cx + f * pl[0] / zl
    v = cy + f * pl[1] / zl
    u0, v0 = np.floor(u).astype(np.int64), np.floor(v).astype(np.int64)
    zbuf = np.full(h * w, np.inf)
    for dv in (0, 1):
        for du in (0, 1):
            uu, vv = u0 + du, v0 + dv
            inside = (uu >= 0) & (uu < w) & (vv >= 0) & (vv < h)
            np.minimum.at(zbuf, vv[inside] * w + uu[inside], zl[inside])
    return zbuf.reshape(h, w)


__all__ = [
    "HIDDEN_MARGIN",
    "MAX_HIDDEN_RADIUS",
    "parallax_bound",
    "render_lidar_depth",
    "rotation_matrix",
    "surface_samples",
    "window_min",
]
