"""A LiDAR point cloud moved into the left camera and projected into a sparse depth map.

Points are moved by the fixed 4 x 4 ``lidar_to_left`` extrinsic (identity = already
in the left optical frame), projected with the left camera's rectified ``P``
(``[u w, v w, w] = P [X Y Z 1]``, depth ``w``), and land on pixel
``(rint(v), rint(u))``; where several land on one pixel the nearest wins. Points
that are not finite, behind the camera (``w <= 0``) or outside the image are
dropped and counted by cause (:class:`CloudCounts`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vpp_service.transport import _points


@dataclass(frozen=True)
class CloudCounts:
    """What became of a cloud's points.

    Attributes
    ----------
    used : int
        Points inside the image, in front of the camera (before nearest-wins merging).
    nonfinite : int
        Points with a NaN/infinite coordinate.
    behind : int
        Points with depth <= 0 in the left camera.
    outside : int
        Points projected outside the image.
    """

    used: int
    nonfinite: int
    behind: int
    outside: int


def check_extrinsic(matrix: np.ndarray) -> np.ndarray:
    """``matrix`` as a 4 x 4 float64 rigid-ish transform (finite, last row ``0 0 0 1``).

    Raises
    ------
    ValueError
        Wrong shape, non-finite values or a last row that is not ``0 0 0 1``.
    """
    m = np.asarray(matrix, dtype=np.float64)
    if m.shape != (4, 4) or not np.all(np.isfinite(m)):
        raise ValueError(f"extrinsic must be a finite 4 x 4 matrix, got shape {m.shape}")
    if not np.array_equal(m[3], [0.0, 0.0, 0.0, 1.0]):
        raise ValueError(f"extrinsic last row must be 0 0 0 1, got {m[3].tolist()}")
    return m


def cloud_to_depth(
    xyz: np.ndarray, lidar_to_left: np.ndarray, p: np.ndarray, shape: tuple[int, int]
) -> tuple[np.ndarray, CloudCounts]:
    """Project N x 3 sensor points into an H x W float32 depth map (metres, NaN = no point).

    Parameters
    ----------
    xyz : ndarray
        N x 3 points in the sensor frame.
    lidar_to_left : ndarray
        4 x 4 transform from the sensor frame to the left optical frame.
    p : ndarray
        3 x 4 projection matrix of the rectified left camera.
    shape : tuple of int
        ``(H, W)`` of the left image.

    Returns
    -------
    (depth map, counts)
    """
    h, w = shape
    cols = np.ascontiguousarray(np.asarray(xyz).reshape(-1, 3).T, dtype=np.float64)  # 3 x N
    n = cols.shape[1]
    out = np.full((h, w), np.nan, np.float32)
    # P [M p; 1] = A p + b: the 3 x 3 product per point written out per row (a BLAS call for
    # an N x 3 by 3 x 3 product costs more than the arithmetic)
    a = p[:, :3] @ lidar_to_left[:3, :3]
    b = p[:, :3] @ lidar_to_left[:3, 3] + p[:, 3]
    x, y, zc = cols
    nonfinite = int(n - np.count_nonzero(np.isfinite(x + y + zc)))
    z = a[2, 0] * x + a[2, 1] * y + a[2, 2] * zc + b[2]  # NaN whenever a coordinate is not finite
    sel = np.flatnonzero(z > 0)
    x, y, zc = cols[:, sel]
    z = z[sel]
    # the scatter kernel tests the bounds in float32: test them on the same float32 values
    u = ((a[0, 0] * x + a[0, 1] * y + a[0, 2] * zc + b[0]) / z).astype(np.float32)
    v = ((a[1, 0] * x + a[1, 1] * y + a[1, 2] * zc + b[1]) / z).astype(np.float32)
    lo = np.float32(-0.5)
    inside = (u >= lo) & (u < np.float32(w - 0.5)) & (v >= lo) & (v < np.float32(h - 0.5))
    m = int(np.count_nonzero(inside))
    uv = np.empty((m, 2), np.float32)
    uv[:, 0], uv[:, 1] = u[inside], v[inside]
    # one pass in Cython: each point on pixel (rint(v), rint(u)), the nearest wins
    bad = _points.scatter_points(uv.reshape(-1), z[inside].astype(np.float32), True, out, _NO_MAP, 0.0, 0.0)
    if bad:  # cannot happen: bounds and depth were checked above
        raise RuntimeError(f"cloud_to_depth: scatter refused the projected points (mask {bad})")
    counts = CloudCounts(used=m, nonfinite=nonfinite, behind=n - nonfinite - sel.size, outside=sel.size - m)
    return out, counts


_NO_MAP = np.empty((0, 0), np.float32)


__all__ = ["CloudCounts", "check_extrinsic", "cloud_to_depth"]
