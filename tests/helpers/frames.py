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


def shifted_pair(h: int, w: int, shift: int, seed: int = 0, channels: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Random texture; ``right(x - shift) = left(x)`` exactly (the left view's disparity is ``shift``)."""
    rng = np.random.default_rng(seed)
    tex = rng.integers(0, 256, (h, w + shift, channels), dtype=np.uint8)
    if channels == 1:
        tex = tex[:, :, 0]
    return np.ascontiguousarray(tex[:, :w]), np.ascontiguousarray(tex[:, shift:])


def noisy_shifted_pair(seed: int, h: int, w: int, shift: int) -> tuple[np.ndarray, np.ndarray]:
    """Smoothed gray noise and a copy shifted by ``shift`` (right(x - shift) = left(x), plus noise)."""
    rng = np.random.default_rng(seed)
    base = rng.integers(0, 256, (h, w + shift)).astype(np.float64)
    base = (base + np.roll(base, 1, 1) + np.roll(base, 1, 0)) / 3
    left = np.clip(base[:, :w] + rng.normal(0, 4, (h, w)), 0, 255).astype(np.uint8)
    right = np.clip(base[:, shift:] + rng.normal(0, 4, (h, w)), 0, 255).astype(np.uint8)
    return left, right
