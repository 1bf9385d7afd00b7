"""Depth <-> disparity conversion and projection of a sensor point cloud to a depth map.

Conventions: ``d = f * b / Z - doffs`` (pixels), ``Z = f * b / (d + doffs)``
(metres).  Missing values are NaN in the outputs of the two conversions;
:func:`points_to_depth_map` returns 0 where no point lands (a valid input for
:func:`depth_to_disparity`, which maps 0 to NaN, and for
:func:`vpp_service.vpp.project`, which treats NaN as "no point").
"""

from __future__ import annotations

import math

import numpy as np


def _check_scalar(name: str, v: object, positive: bool) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name} must be a number, got {type(v).__name__}")
    v = float(v)
    if not math.isfinite(v) or (positive and v <= 0):
        raise ValueError(f"{name} must be finite{' and > 0' if positive else ''}, got {v}")
    return v


def _check_map(name: str, a: object) -> np.ndarray:
    if not isinstance(a, np.ndarray):
        raise TypeError(f"{name} must be a numpy.ndarray, got {type(a).__name__}")
    if a.dtype.kind != "f":
        raise TypeError(f"{name} must have a floating dtype, got {a.dtype}")
    return a


def depth_to_disparity(depth: np.ndarray, f: float, baseline: float, doffs: float = 0.0) -> np.ndarray:
    """Disparity ``f * baseline / Z - doffs`` of a depth map.

    Parameters
    ----------
    depth : numpy.ndarray
        Depth in metres, any shape, floating dtype.  0, NaN, inf and negative
        values mean "no depth".
    f : float
        Focal length, pixels (> 0).
    baseline : float
        Baseline, metres (> 0).
    doffs : float
        Principal-point offset, pixels.  Default 0.

    Returns
    -------
    numpy.ndarray
        float32, NaN where the depth is missing (or the disparity is not > 0).
    """
    depth = _check_map("depth", depth)
    f = _check_scalar("f", f, True)
    baseline = _check_scalar("baseline", baseline, True)
    doffs = _check_scalar("doffs", doffs, False)
    # Sensor maps are mostly empty: convert only the valid pixels (float64
    # arithmetic) instead of round-tripping the whole map.
    flat = depth.reshape(-1)
    idx = np.flatnonzero(np.isfinite(flat) & (flat > 0))
    d = f * baseline / flat[idx].astype(np.float64) - doffs
    keep = d > 0
    out = np.full(depth.shape, np.nan, dtype=np.float32)
    out.reshape(-1)[idx[keep]] = d[keep].astype(np.float32)
    return out


def disparity_to_depth(disparity: np.ndarray, f: float, baseline: float, doffs: float = 0.0) -> np.ndarray:
    """Depth ``f * baseline / (d + doffs)`` of a disparity map.

    Parameters
    ----------
    disparity : numpy.ndarray
        Disparity in pixels, floating dtype; 0/NaN/inf/negative = missing.
    f, baseline, doffs : float
        As in :func:`depth_to_disparity`.

    Returns
    -------
    numpy.ndarray
        float32 metres, NaN where missing.
    """
    disparity = _check_map("disparity", disparity)
    f = _check_scalar("f", f, True)
    baseline = _check_scalar("baseline", baseline, True)
    doffs = _check_scalar("doffs", doffs, False)
    d = disparity.astype(np.float64)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        den = d + doffs
        ok = np.isfinite(d) & (d > 0) & (den > 0)
        # dense divide + select: no boolean gather/scatter
        out = np.where(ok, (f * baseline) / den, np.nan)
    return out.astype(np.float32)


def points_to_depth_map(
    points_xyz: np.ndarray, K: np.ndarray, T_cam_from_sensor: np.ndarray, shape: tuple[int, int]
) -> np.ndarray:
    """Project a sensor point cloud into the left camera as a sparse depth map.

    Points are moved with ``T_cam_from_sensor`` (4x4), kept if finite with
    ``z > 0``, projected with ``K`` to ``(u, v) = (fx X/Z + cx, fy Y/Z + cy)``
    (plus skew), and land on pixel ``(floor(u + 0.5), floor(v + 0.5))`` if it
    is inside the image; where several land on one pixel the nearest wins.

    Parameters
    ----------
    points_xyz : numpy.ndarray
        N x 3 floating points in the sensor frame (N may be 0).
    K : numpy.ndarray
        3 x 3 intrinsics of the left camera.
    T_cam_from_sensor : numpy.ndarray
        4 x 4 rigid transform from the sensor to the camera frame.
    shape : tuple of int
        ``(H, W)`` of the image.

    Returns
    -------
    numpy.ndarray
        H x W float32 depth in metres, 0 where no point lands.
    """
    pts = points_xyz
    if not isinstance(pts, np.ndarray):
        raise TypeError(f"points_xyz must be a numpy.ndarray, got {type(pts).__name__}")
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points_xyz must be N x 3, got shape {pts.shape}")
    if pts.dtype.kind not in "fiu":
        raise TypeError(f"points_xyz must be numeric, got {pts.dtype}")
    for name, m, sh in (("K", K, (3, 3)), ("T_cam_from_sensor", T_cam_from_sensor, (4, 4))):
        if not isinstance(m, np.ndarray):
            raise TypeError(f"{name} must be a numpy.ndarray, got {type(m).__name__}")
        if m.shape != sh:
            raise ValueError(f"{name} must have shape {sh}, got {m.shape}")
        if not np.all(np.isfinite(m)):
            raise ValueError(f"{name} must be finite")
    if (
        not isinstance(shape, (tuple, list))
        or len(shape) != 2
        or not all(isinstance(s, (int, np.integer)) and not isinstance(s, bool) and s > 0 for s in shape)
    ):
        raise ValueError(f"shape must be (H, W) with positive ints, got {shape!r}")
    H, W = int(shape[0]), int(shape[1])
    out = np.zeros((H, W), dtype=np.float32)
    if pts.shape[0] == 0:
        return out
    p = pts.astype(np.float64)
    T = T_cam_from_sensor.astype(np.float64)
    cam = p @ T[:3, :3].T + T[:3, 3]
    z = cam[:, 2]
    ok = np.isfinite(cam).all(axis=1) & (z > 0)
    cam, z = cam[ok], z[ok]
    uvw = cam @ K.astype(np.float64).T
    u = np.floor(uvw[:, 0] / uvw[:, 2] + 0.5)
    v = np.floor(uvw[:, 1] / uvw[:, 2] + 0.5)
    ok = np.isfinite(u) & np.isfinite(v) & (u >= 0) & (u < W) & (v >= 0) & (v < H)
    u, v, z = u[ok].astype(np.int64), v[ok].astype(np.int64), z[ok]
    if z.size == 0:
        return out
    lin = v * W + u
    order = np.lexsort((z, lin))  # by pixel, nearest first
    lin, z = lin[order], z[order]
    first = np.ones(lin.size, dtype=bool)
    first[1:] = lin[1:] != lin[:-1]
    out.reshape(-1)[lin[first]] = z[first].astype(np.float32)
    return out
