"""Projection of a Velodyne scan (KITTI ``velodyne/*.bin``) into a camera depth map.

The projection follows the same rules as ``vpp_service.vpp.points_to_depth_map``
(keep z > 0 and pixels inside the image, pixel ``floor(u + 0.5)``, the nearest
point wins a pixel) but takes KITTI's full 3 x 4 rectified projection matrix:
``P2``/``P3`` carry a translation column that a 3 x 3 ``K`` would drop.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def read_velodyne_bin(path: str | Path) -> np.ndarray:
    """Read a KITTI Velodyne scan: N x 4 float32 (x, y, z, reflectance), metres."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"path: velodyne scan not found: {path}")
    raw = np.fromfile(path, dtype="<f4")
    if raw.size % 4:
        raise ValueError(f"path: {path} size is not a multiple of 4 float32 values")
    return raw.reshape(-1, 4).astype(np.float32)


def velo_to_camera(points: np.ndarray, tr_velo_to_cam: np.ndarray, r0_rect: np.ndarray | None = None) -> np.ndarray:
    """Transform N x 3(+) LiDAR points to the rectified camera frame: ``R0 @ (Tr @ [x y z 1])``."""
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] < 3:
        raise ValueError(f"points: must be N x 3 or N x 4, got shape {pts.shape}")
    tr = np.asarray(tr_velo_to_cam, dtype=np.float64).reshape(3, 4)
    cam = pts[:, :3] @ tr[:, :3].T + tr[:, 3]
    if r0_rect is not None:
        cam = cam @ np.asarray(r0_rect, dtype=np.float64).reshape(3, 3).T
    return cam


def project_points(points_cam: np.ndarray, p_rect: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Z-buffer projection of camera-frame points into an H x W depth map.

    Parameters
    ----------
    points_cam : ndarray
        N x 3 points in the rectified camera frame (metres, z forward).
    p_rect : ndarray
        3 x 4 (or 3 x 3) projection matrix of the image.
    shape : (int, int)
        Image height and width.

    Returns
    -------
    ndarray
        H x W float32 depth (z, metres); 0 where no point landed; the smallest
        z wins when several points fall on one pixel.
    """
    pts = np.asarray(points_cam, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points_cam: must be N x 3, got shape {pts.shape}")
    h, w = int(shape[0]), int(shape[1])
    if h <= 0 or w <= 0:
        raise ValueError(f"shape: must be positive, got {shape}")
    p = np.asarray(p_rect, dtype=np.float64)
    if p.shape == (3, 3):
        p = np.hstack([p, np.zeros((3, 1))])
    if p.shape != (3, 4):
        raise ValueError(f"p_rect: must be 3 x 4 or 3 x 3, got {p.shape}")
    pts = pts[np.isfinite(pts).all(axis=1) & (pts[:, 2] > 0)]
    hom = pts @ p[:, :3].T + p[:, 3]
    z = hom[:, 2]
    keep = z > 0
    u = np.floor(hom[keep, 0] / z[keep] + 0.5).astype(np.int64)
    v = np.floor(hom[keep, 1] / z[keep] + 0.5).astype(np.int64)
    depth_z = pts[keep, 2]
    inside = (u >= 0) & (u < w) & (v >= 0) & (v < h)
    u, v, depth_z = u[inside], v[inside], depth_z[inside]
    depth = np.full(h * w, np.inf)
    np.minimum.at(depth, v * w + u, depth_z)
    depth[~np.isfinite(depth)] = 0.0
    return depth.reshape(h, w).astype(np.float32)


__all__ = ["project_points", "read_velodyne_bin", "velo_to_camera"]
