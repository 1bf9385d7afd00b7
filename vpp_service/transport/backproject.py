"""A depth map back-projected into a point cloud in the (rectified) left camera's optical frame.

The one back-projection every points output uses (ROS 2 ``points2``, Zenoh ``out/points``,
the files sink's ``.ply``, Rerun's ``Points3D``): pixel ``(v, u)`` with depth ``z`` (metres)
is the point

    ``x = (u - cx) z / f``,  ``y = (v - cy) z / f``,  ``z``

(x right, y down, z forward; pixel centres at integer coordinates, OpenCV's convention).
``cx``, ``cy`` come from the calibration, else the image centre ``((W - 1) / 2, (H - 1) / 2)``.
A pixel is a point only where its depth is finite and > 0: the service's depth clip
(:mod:`vpp_service.matchers.depth_clip`) has already made every depth outside the valid
range NaN, so the points keep to it. ``stride`` keeps every ``stride``-th row and column
(pixels ``(i s, j s)``), bounding the cost: at the default :data:`DEFAULT_STRIDE` a 720p
frame has at most 320 x 180 = 57 600 points.
"""

from __future__ import annotations

import numpy as np

from vpp_service.frame import Calibration

#: Default ``points_stride`` of the Zenoh, files and Rerun points outputs.
DEFAULT_STRIDE = 4
#: Largest accepted ``points_stride``.
MAX_STRIDE = 64


def check_stride(stride: object, key: str = "points_stride") -> int:
    """``stride`` as an int in ``[1, MAX_STRIDE]``.

    Raises
    ------
    ValueError
        Not an integer in that range; the message names ``key``.
    """
    if isinstance(stride, bool) or not isinstance(stride, (int, np.integer)) or not 1 <= stride <= MAX_STRIDE:
        raise ValueError(
            f"{key}: must be an integer in [1, {MAX_STRIDE}] (1 = every pixel, s = every s-th row and column), "
            f"got {stride!r}"
        )
    return int(stride)


def principal_point(calib: Calibration, shape: tuple[int, ...]) -> tuple[float, float]:
    """``(cx, cy)`` of ``calib``, else the centre of an image of ``shape`` ``(H, W, ...)``."""
    h, w = shape[:2]
    cx = float(calib.cx) if calib.cx is not None else (w - 1) / 2.0
    cy = float(calib.cy) if calib.cy is not None else (h - 1) / 2.0
    return cx, cy


def depth_to_points(
    depth: np.ndarray,
    image: np.ndarray | None,
    calib: Calibration,
    *,
    stride: int = 1,
    organized: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """A depth map as N x 3 float32 points in the left optical frame and N x 3 uint8 colours.

    Parameters
    ----------
    depth : ndarray
        H x W metric depth (metres; NaN, inf or <= 0 = no point).
    image : ndarray or None
        The left image the colours come from, H x W (grey) or H x W x 3 (RGB) uint8;
        None = mid grey.
    calib : Calibration
        ``f`` (pixels) and the principal point (see :func:`principal_point`).
    stride : int
        Keep pixels ``(i stride, j stride)`` only (see :func:`check_stride`).
    organized : bool
        Every kept pixel, row by row (N = rows x columns of the strided grid), NaN where the
        depth is not valid (the colour kept, as stereo_image_proc does); else (default) the
        valid pixels only, in raster order.

    Returns
    -------
    (xyz, rgb)
        ``xyz`` N x 3 float32 ``(x, y, z)`` metres, ``rgb`` N x 3 uint8.

    Raises
    ------
    ValueError
        ``depth`` not 2-D, ``image`` of another size, a bad ``stride`` or a calibration
        whose ``f`` is not finite and > 0.
    """
    s = check_stride(stride, "stride")
    if depth.ndim != 2:
        raise ValueError(f"depth must be an H x W map, got shape {depth.shape}")
    if image is not None and image.shape[:2] != depth.shape:
        raise ValueError(f"image {image.shape[:2]} and depth {depth.shape} differ in size")
    if not (np.isfinite(calib.f) and calib.f > 0):
        raise ValueError(f"calibration f must be finite and > 0, got {calib.f}")
    cx, cy = principal_point(calib, depth.shape)
    d = depth[::s, ::s]
    valid = np.isfinite(d) & (d > 0)
    if image is None:
        grid_rgb = np.full((*d.shape, 3), 128, np.uint8)
    else:
        sub = image[::s, ::s]
        grid_rgb = sub if sub.ndim == 3 else np.repeat(sub[:, :, None], 3, axis=2)
    if organized:
        i, j = np.mgrid[0 : d.shape[0], 0 : d.shape[1]].reshape(2, -1)
        z = np.where(valid, d, np.nan).reshape(-1).astype(np.float64)
        rgb = grid_rgb.reshape(-1, 3)
    else:
        i, j = np.nonzero(valid)
        z = d[valid].astype(np.float64)
        rgb = grid_rgb[valid]
    u, v = j * s, i * s  # pixel coordinates in the full image
    xyz = np.empty((z.size, 3), np.float32)
    xyz[:, 0] = (u - cx) * z / calib.f
    xyz[:, 1] = (v - cy) * z / calib.f
    xyz[:, 2] = z
    return xyz, np.ascontiguousarray(rgb, dtype=np.uint8)


__all__ = ["DEFAULT_STRIDE", "MAX_STRIDE", "check_stride", "depth_to_points", "principal_point"]
