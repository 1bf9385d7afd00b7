"""Scenes with ground truth as ROS 2 stereo rigs (for the ros2 and rosbag2 service tests), and their msgpack reference.

* ``motorcycle``: scikit-image's Middlebury 2014 Motorcycle (RGB, ships with the package).
* ``kitti``: the KITTI 2012 training frame 000070 of the shared data (``<repo>/../shared/data``), read
  in place with the project's KITTI reader: the gray pair (published as ``mono8``) and camera_info
  carrying the file's real ``P0``/``P1``.

Each rig's cloud is a sparse random sample of the valid ground-truth pixels back-projected into the
left optical frame with the rig's projections (``Z = f B / (d + doffs)``, ``doffs = cx_r - cx_l``).
:func:`msgpack_bad2` sends the same frame (same points, same pattern seed) through the msgpack wire
format and :func:`~vpp_service.fusion.fuse`, the reference the ROS paths must match.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from helpers.ros2_robot import StereoRig
from helpers.shared_data import SHARED_DATA, need_shared
from vpp_service.frame import Calibration, StereoFrame
from vpp_service.fusion import fuse
from vpp_service.matchers import build_matcher
from vpp_service.metrics import compute_metrics
from vpp_service.transport import wire
from vpp_service.vpp import VPPConfig

KITTI_FRAME = SHARED_DATA / "kitti2012_training" / "000070"
KITTI_ID = "000070"

#: The scene names, as test ids.
SCENES = ("motorcycle", "kitti")


@dataclass
class RigScene:
    """A rig with its ground truth.

    Attributes
    ----------
    rig : StereoRig
        What the robot publishes / the bag holds.
    gt : ndarray
        H x W float32 ground-truth disparity of the left view (NaN = none), project units (``x_l - x_r``).
    calib : Calibration
        The scene's calibration as the project reads it (the msgpack path's).
    max_disparity : int
        The matcher's disparity range for this scene.
    """

    rig: StereoRig
    gt: np.ndarray
    calib: Calibration
    max_disparity: int


def ground_truth_cloud(
    gt: np.ndarray, p_left: np.ndarray, p_right: np.ndarray, density: float, seed: int
) -> np.ndarray:
    """N x 3 float32 points in the left optical frame: ``density`` of the valid ``gt`` pixels, back-projected."""
    f = float(p_right[0, 0])
    baseline = float(-p_right[0, 3] / p_right[0, 0])
    doffs = float(p_right[0, 2] - p_left[0, 2])
    rng = np.random.default_rng(seed)
    vs, us = np.nonzero(np.isfinite(gt))
    pick = rng.random(vs.size) < density
    vs, us = vs[pick], us[pick]
    z = f * baseline / (gt[vs, us].astype(np.float64) + doffs)
    # [u z, v z, z] = P_left[:, :3] X + P_left[:, 3]
    rhs = np.stack([us * z, vs * z, z]) - p_left[:, 3:4]
    return np.linalg.solve(p_left[:, :3], rhs).T.astype(np.float32)


def motorcycle_scene(density: float = 0.05, seed: int = 0) -> RigScene:
    """The scikit-image Motorcycle scene (RGB), principal point at the image centre."""
    from vpp_service.datasets.skimage_scene import MOTORCYCLE_CALIB, motorcycle_arrays

    left, right, gt = motorcycle_arrays()
    c = MOTORCYCLE_CALIB
    h, w = gt.shape
    cx, cy = (w - 1) / 2, (h - 1) / 2
    p_left = np.array([[c.f, 0, cx, 0], [0, c.f, cy, 0], [0, 0, 1.0, 0]])
    p_right = np.array([[c.f, 0, cx + c.doffs, -c.f * c.baseline], [0, c.f, cy, 0], [0, 0, 1.0, 0]])
    cloud = ground_truth_cloud(gt, p_left, p_right, density, seed)
    calib = Calibration(f=c.f, baseline=c.baseline, doffs=c.doffs, cx=cx, cy=cy)
    return RigScene(StereoRig.from_projections(left, right, p_left, p_right, cloud), gt, calib, 96)


def kitti_scene(density: float = 0.05, seed: int = 0) -> RigScene:
    """KITTI 2012 frame 000070 (gray pair, real ``P0``/``P1``) read in place from the shared data.

    Skips the calling test, naming the path, when the shared data is not beside the repository
    (fails it where ``$VPP_REQUIRE_SHARED_DATA`` is set: see :mod:`helpers.shared_data`).
    """
    from vpp_service.datasets.calibfile import parse_kitti_calib
    from vpp_service.datasets.kitti import Kitti2012

    need_shared("kitti2012_training/000070")
    reader = Kitti2012(KITTI_FRAME)
    frame = reader[f"{KITTI_ID}_10"]
    assert frame.gt_disparity is not None and frame.calib is not None, frame.meta
    entries = parse_kitti_calib(KITTI_FRAME / "calib" / f"{KITTI_ID}.txt")
    p_left, p_right = entries[f"P{reader.p_left}"], entries[f"P{reader.p_right}"]
    gt = frame.gt_disparity
    cloud = ground_truth_cloud(gt, p_left, p_right, density, seed)
    rig = StereoRig.from_projections(frame.left, frame.right, p_left, p_right, cloud)
    return RigScene(rig, gt, frame.calib, 160)  # ground truth reaches 147 px


def load_scene(name: str) -> RigScene:
    """The scene ``name`` (one of :data:`SCENES`)."""
    return {"motorcycle": motorcycle_scene, "kitti": kitti_scene}[name]()


def msgpack_bad2(scene: RigScene) -> float:
    """bad-2 of the scene's frame (its cloud as sensor depth, pattern seed 1) through the msgpack wire format."""
    rig = scene.rig
    h, w = scene.gt.shape
    p = rig.projection(right=False)
    uvw = p[:, :3] @ rig.cloud.T.astype(np.float64) + p[:, 3:4]
    u = np.rint(uvw[0] / uvw[2]).astype(int)
    v = np.rint(uvw[1] / uvw[2]).astype(int)
    z = np.full((h, w), np.nan, np.float32)
    z[v, u] = uvw[2].astype(np.float32)
    frame = StereoFrame(left=rig.left, right=rig.right, calib=scene.calib, sensor_depth=z, seq=1)
    frame = wire.decode_frame(wire.encode_frame(frame))
    matcher = build_matcher("sgbm", {"max_disparity": scene.max_disparity})
    res = fuse(frame, matcher, VPPConfig(), seed=1, depth=False)
    return compute_metrics(res.disparity, scene.gt)["bad2"]


def plain_bad2(scene: RigScene) -> float:
    """bad-2 of the scene's pair matched without VPP (what the sparse depth must improve on)."""
    matcher = build_matcher("sgbm", {"max_disparity": scene.max_disparity})
    res = fuse(StereoFrame(left=scene.rig.left, right=scene.rig.right), matcher, depth=False)
    return compute_metrics(res.disparity, scene.gt)["bad2"]


__all__ = [
    "KITTI_FRAME",
    "SCENES",
    "SHARED_DATA",
    "RigScene",
    "ground_truth_cloud",
    "kitti_scene",
    "load_scene",
    "motorcycle_scene",
    "msgpack_bad2",
    "plain_bad2",
]
