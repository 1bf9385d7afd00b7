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
    cam = pts @ lidar_to_left[:3, :3].T + lidar_to_left[:3, 3]
    proj = cam @ p[:, :3].T + p[:, 3]
    z = proj[:, 2]
    front = z > 0
    proj, z = proj[front], z[front]
    u, v = proj[:, 0] / z, proj[:, 1] / z
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
