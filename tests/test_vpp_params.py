"""Tests of vpp_service.vpp.params: the one translation of a VPPConfig for the kernel."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vpp_service.vpp import VPPConfig, backend, detect_occlusions
from vpp_service.vpp._sweep import Occlusion, PatchMask, Pattern
from vpp_service.vpp.params import adaptive_range, kernel_params


def test_named_modes_and_derived_fields():
    cfg = VPPConfig(
        pattern="histogram",
        occlusion="no",
        adaptive_patch="bilateral",
        patch=5,
        uniform_patch=True,
        bilateral_sigma_space=3.0,
        bilateral_sigma_color=0.5,
        bilateral_threshold=0.01,
    )
    p = kernel_params(cfg)
    assert p["pattern"] == Pattern.HISTOGRAM and p["occlusion"] == Occlusion.OCC_NO
    assert p["mask"] == PatchMask.MASK_BILATERAL
    assert p["hmax"] == 2 and p["uniform"] is True
    assert p["two_ss"] == 18.0 and p["two_sc"] == 0.5 and p["neglogthr"] == -math.log(0.01)
    defaults = kernel_params(VPPConfig())
    assert (defaults["pattern"], defaults["occlusion"], defaults["mask"]) == (
        Pattern.RANDOM,
        Occlusion.OCC_FGD,
        PatchMask.MASK_FULL,
    )
    # a one-pixel patch is the same whether uniform or not: the per-pixel path
    assert kernel_params(VPPConfig(patch=1, uniform_patch=True))["uniform"] is False


def test_adaptive_range_over_valid_points_only():
    d = np.zeros((3, 10), np.float32)
    d[0, :4] = [2.5, -1.0, np.nan, 10.0]  # 10 >= W: invalid
    d[1, 2] = 7.25
    d[2, 9] = np.inf
    cfg = VPPConfig(adaptive_patch="distance")
    assert adaptive_range(cfg, d) == (2.5, 7.25)
    assert adaptive_range(VPPConfig(adaptive_patch="distance", adaptive_max_disparity=30.0), d) == (2.5, 30.0)
    assert adaptive_range(cfg, np.zeros((2, 2), np.float32)) == (0.0, 0.0)
    p = kernel_params(cfg, d)
    assert (p["adaptive_dmin"], p["adaptive_dmax"]) == (2.5, 7.25)
    assert (kernel_params(VPPConfig(), d)["adaptive_dmin"], kernel_params(VPPConfig(), d)["adaptive_dmax"]) == (0, 0)


def test_kernel_rejects_incomplete_params():
    d = np.zeros((4, 8), np.float32)
    p = dict(kernel_params(VPPConfig()))
    del p["occ_t"]
    with pytest.raises((TypeError, ValueError), match="occ_t"):
        backend.sweep.occlusions(d, np.zeros((4, 8), np.uint8), p, 1)


def test_kernel_checks_shapes():
    d = np.zeros((4, 8), np.float32)
    img = np.zeros((4, 8, 3), np.uint8)
    p = kernel_params(VPPConfig(pattern="histogram"))
    with pytest.raises(ValueError, match="occ"):
        backend.sweep.occlusions(d, np.zeros((4, 7), np.uint8), p, 1)
    with pytest.raises(ValueError, match="shapes"):
        backend.sweep.paint(d, np.zeros((4, 8), np.uint8), img, img[:, :7].copy(), img.copy(), img.copy(), p, None, 1)


def test_detect_occlusions_accepts_numpy_scalars():
    rng = np.random.default_rng(3)
    d = np.where(rng.random((20, 40)) < 0.2, rng.uniform(0.5, 30, (20, 40)), 0).astype(np.float32)
    ref = detect_occlusions(d, window=(5, 3), lam=1.5, gamma=0.25, t=0.5)
    got = detect_occlusions(
        d, window=(np.int64(5), np.int32(3)), lam=np.float32(1.5), gamma=np.float64(0.25), t=np.float32(0.5)
    )
    np.testing.assert_array_equal(got, ref)
