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
    pts = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    out = np.full((h, w), np.nan, np.float32)
    finite = np.all(np.isfinite(pts), axis=1)
    pts = pts[finite]
    # P [M p; 1] = A p + b: one 3 x 3 product per point, written out per column (a BLAS call
    # for an N x 3 by 3 x 3 product costs more than the arithmetic)
    a = p[:, :3] @ lidar_to_left[:3, :3]
    b = p[:, :3] @ lidar_to_left[:3, 3] + p[:, 3]
    x, y, zc = pts[:, 0], pts[:, 1], pts[:, 2]
    z = a[2, 0] * x + a[2, 1] * y + a[2, 2] * zc + b[2]
    front = z > 0
    x, y, zc, z = x[front], y[front], zc[front], z[front]
    proj = np.empty((z.size, 2))
    for row in range(2):
        proj[:, row] = (a[row, 0] * x + a[row, 1] * y + a[row, 2] * zc + b[row]) / z
    u, v = proj[:, 0], proj[:, 1]
    inside = (u >= -0.5) & (u < w - 0.5) & (v >= -0.5) & (v < h - 0.5)
    u, v, z = u[inside], v[inside], z[inside]
    lin = np.rint(v).astype(np.int64) * w + np.rint(u).astype(np.int64)
    order = np.lexsort((z, lin))  # by pixel, nearest first
    lin_s = lin[order]
    first = np.ones(lin_s.size, bool)
    first[1:] = lin_s[1:] != lin_s[:-1]
    out.reshape(-1)[lin_s[first]] = z[order][first].astype(np.float32)
    counts = CloudCounts(
        used=int(lin.size),
        nonfinite=int((~finite).sum()),
        behind=int((~front).sum()),
        outside=int((~inside).sum()),
    )
    return out, counts


__all__ = ["CloudCounts", "check_extrinsic", "cloud_to_depth"]
