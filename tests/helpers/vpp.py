"""Shared VPP test helpers: random cases and the kernel builds (fixture ``build`` in conftest)."""

from __future__ import annotations

from types import ModuleType

import numpy as np

from vpp_service.vpp import backend

#: the builds of the sweep kernel (None: not runnable on this CPU / platform)
BUILDS: dict[str, ModuleType | None] = {"portable": backend.portable, "avx2": backend.avx2_build()}


def make_case(
    rng: np.random.Generator, H: int, W: int, C: int, density: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Random smooth+noisy images and a sparse disparity with border, colliding and invalid points."""
    base = rng.integers(0, 256, (H, W, C)).astype(np.float64)
    base = 0.5 * base + 0.5 * np.roll(base, 1, axis=1)
    left = np.clip(base + rng.normal(0, 10, base.shape), 0, 255).astype(np.uint8)
    right = np.clip(np.roll(base, -3, axis=1) + rng.normal(0, 10, base.shape), 0, 255).astype(np.uint8)
    disp = np.zeros((H, W), np.float32)
    m = rng.random((H, W)) < density
    disp[m] = rng.uniform(0.2, W * 0.6, m.sum()).astype(np.float32)
    k = rng.random((H, W)) < density * 0.3  # integer disparities
    disp[k] = rng.integers(1, max(2, W // 2), k.sum()).astype(np.float32)
    for _ in range(3):  # colliding pairs (same warped cell)
        y, x1 = rng.integers(0, H), rng.integers(0, W - 8)
        d1 = float(rng.integers(2, 6))
        disp[y, x1], disp[y, x1 + 4] = d1, d1 + 4.2
    y = rng.integers(0, H)
    disp[y, 1] = 3.7  # left-border point
    bad = rng.integers(0, H * W, 4)
    disp.reshape(-1)[bad] = np.array([-2.0, np.inf, np.nan, W + 1.0], np.float32)
    if C == 1 and rng.random() < 0.5:
        left, right = left[:, :, 0], right[:, :, 0]
    return left, right, disp
