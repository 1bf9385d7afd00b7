"""Small deterministic stereo frames for wire-format, source and sink tests."""

from __future__ import annotations

import numpy as np

from vpp_service.frame import Calibration, StereoFrame


def make_frame(h: int = 6, w: int = 8, c: int = 3, seed: int = 0, depth: str = "metric") -> StereoFrame:
    """A random ``h x w`` pair (``c`` = 1 or 3 channels) with calibration, ground truth and two depth points.

    ``depth = "metric"`` attaches the points as ``sensor_depth`` (metres), anything
    else as ``sparse_disparity`` (pixels). Identity: rig ``r1``, seq 7, stamp 123456789.
    """
    rng = np.random.default_rng(seed)
    shape = (h, w) if c == 1 else (h, w, 3)
    left = rng.integers(0, 256, shape, dtype=np.uint8)
    right = rng.integers(0, 256, shape, dtype=np.uint8)
    gt = rng.uniform(1, 5, (h, w)).astype(np.float32)
    calib = Calibration(f=100.0, baseline=0.1, doffs=2.0)
    sparse = np.full((h, w), np.nan, np.float32)
    sparse[1, 2], sparse[3, 5] = 2.5, 4.0
    z = np.full((h, w), np.nan, np.float32)
    z[1, 2], z[3, 5] = 1.5, 3.25
    return StereoFrame(
        left=left,
        right=right,
        calib=calib,
        gt_disparity=gt,
        sparse_disparity=None if depth == "metric" else sparse,
        sensor_depth=z if depth == "metric" else None,
        rig="r1",
        seq=7,
        stamp_ns=123456789,
    )
