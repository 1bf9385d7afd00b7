"""A raw, distorted, unrectified stereo rig made from a rectified pair and a known calibration.

:func:`rig_calibration` is a mild, realistic camera_info pair (plumb_bob ``k1 = -0.12``, raw
intrinsics a little off the rectified ones, each camera rotated by under 1 degree), whose
rectified cameras are exactly the given rectified pair's (``fx' = f``, the same ``cx'``, ``cy'``):
the ground truth of the rectified pair stays the truth of the rig's rectified output.
:func:`raw_image` synthesises what such a camera would have captured, the inverse of
rectification: each raw pixel samples the rectified image at its ``undistortPoints(K, D, R, P)``
position (bicubic: a camera blurs less than a bilinear resampling). Nothing here uses the
project's rectifier.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import cv2
import numpy as np

from vpp_service.rectify import CameraInfo, write_camera_info


def _rotation(rx_deg: float, ry_deg: float, rz_deg: float) -> np.ndarray:
    r, _ = cv2.Rodrigues(np.deg2rad([rx_deg, ry_deg, rz_deg]))
    return r


def rig_calibration(width: int, height: int, f: float = 420.0, baseline: float = 0.16) -> tuple[CameraInfo, CameraInfo]:
    """Left and right camera_info of a mildly distorted, mildly rotated rig (rectified to focal ``f``)."""
    cx, cy = (width - 1) / 2.0, (height - 1) / 2.0
    p_left = np.array([[f, 0, cx, 0], [0, f, cy, 0], [0, 0, 1, 0]], dtype=np.float64)
    p_right = p_left.copy()
    p_right[0, 3] = -f * baseline
    cams = []
    for view, (df, dcx, dcy, rot, d) in enumerate(
        (
            (6.0, 3.5, -2.0, (0.4, -0.6, 0.3), [-0.12, 0.03, 0.0008, -0.0005, 0.0]),
            (-4.0, -2.5, 1.5, (-0.5, 0.7, -0.4), [-0.12, 0.025, -0.0006, 0.0007, 0.0]),
        )
    ):
        k = np.array([[f + df, 0, cx + dcx], [0, f + df * 1.01, cy + dcy], [0, 0, 1]], dtype=np.float64)
        cams.append(
            CameraInfo(
                width,
                height,
                k,
                np.array(d),
                _rotation(*rot),
                p_left if view == 0 else p_right,
                "plumb_bob",
                name=("left", "right")[view],
            )
        )
    return cams[0], cams[1]


def raw_image(rectified: np.ndarray, info: CameraInfo) -> np.ndarray:
    """The raw image ``info``'s camera would capture of ``rectified`` (0 where the rectified image ends)."""
    h, w = info.height, info.width
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    pts = np.stack([u.ravel(), v.ravel()], axis=1).reshape(-1, 1, 2)
    rect = cv2.undistortPoints(pts, info.k, info.d, R=info.r, P=info.p).reshape(h, w, 2).astype(np.float32)
    return cv2.remap(rectified, rect[..., 0], rect[..., 1], cv2.INTER_CUBIC, borderMode=cv2.BORDER_CONSTANT)


def write_rig_yamls(folder: Path, width: int, height: int) -> tuple[Path, Path]:
    """``left.yaml`` and ``right.yaml`` (camera_calibration's layout) of :func:`rig_calibration` in ``folder``."""
    left, right = rig_calibration(width, height)
    paths = folder / "left.yaml", folder / "right.yaml"
    write_camera_info(paths[0], left, "left")
    write_camera_info(paths[1], right, "right")
    return paths


def write_raw_scene(folder: Path, root: Path, scene: str) -> tuple[Path, Path, Path]:
    """A Middlebury 2005/2006 scene as the rig would capture it: ``(raw root, left.yaml, right.yaml)``.

    ``<folder>/raw/<scene>/view1.png, view5.png`` are the raw images; the ground truth
    (``disp1.png``, ``disp5.png``) is the scene's own: it describes the rectified output.
    """
    from vpp_service.datasets import open_dataset

    frame = open_dataset("middlebury2006", root).select([scene])[0]
    h, w = frame.shape
    left, right = rig_calibration(w, h)
    out = folder / "raw" / scene
    out.mkdir(parents=True)
    for name, img, info in (("view1.png", frame.left, left), ("view5.png", frame.right, right)):
        cv2.imwrite(str(out / name), cv2.cvtColor(raw_image(img, info), cv2.COLOR_RGB2BGR))
    for gt in ("disp1.png", "disp5.png"):
        shutil.copy(root / scene / gt, out / gt)
    return (folder / "raw", *write_rig_yamls(folder, w, h))
