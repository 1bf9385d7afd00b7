"""Tests of vpp_service.vpp.detect_occlusions against the dense-grid literal reference."""

from __future__ import annotations

import numpy as np
import pytest

from vpp_reference import ref_occlusions
from vpp_service.vpp import detect_occlusions


@pytest.mark.parametrize("seed", range(12))
@pytest.mark.parametrize(
    "params", [dict(), dict(window=(3, 1), lam=0.5, gamma=1.0, t=0.0), dict(window=(15, 9), lam=1.0, gamma=0.2, t=2.0)]
)
def test_matches_reference(seed, params):
    rng = np.random.default_rng(seed)
    H, W = int(rng.integers(5, 30)), int(rng.integers(10, 60))
    disp = np.where(rng.random((H, W)) < rng.choice([0.05, 0.3, 0.8]), rng.uniform(0.1, W * 0.7, (H, W)), 0).astype(
        np.float32
    )
    k = rng.random((H, W)) < 0.2
    disp[k] = rng.integers(1, W // 2 + 1, k.sum())
    disp[0, 0] = np.nan
    occ = detect_occlusions(disp, threads=2, **params)
    ref = ref_occlusions(disp, **{"window": (9, 7), "lam": 2.0, "gamma": 0.4375, "t": 1.0, **params})
    np.testing.assert_array_equal(occ, ref)


def test_foreground_background_pair():
    disp = np.zeros((9, 40), np.float32)
    disp[4, 20] = 5.0  # background, warps to 15
    disp[4, 27] = 10.0  # foreground, warps to 17: 10 - 5 - 2*0.4375*2 > 1
    occ = detect_occlusions(disp)
    assert occ[4, 20] and not occ[4, 27]
    assert occ.sum() == 1


def test_flat_disparity_has_no_occlusion():
    disp = np.zeros((20, 30), np.float32)
    disp[::2, ::3] = 7.5
    assert not detect_occlusions(disp).any()


def test_thread_count_invariant():
    rng = np.random.default_rng(0)
    disp = np.where(rng.random((200, 300)) < 0.1, rng.uniform(0.5, 100, (200, 300)), 0).astype(np.float32)
    a = detect_occlusions(disp, threads=1)
    b = detect_occlusions(disp, threads=2)
    np.testing.assert_array_equal(a, b)
    assert a.any()


@pytest.mark.parametrize(
    ("kwargs", "exc"),
    [
        (dict(window=(8, 7)), ValueError),
        (dict(window=(9,)), TypeError),
        (dict(lam=-1.0), ValueError),
        (dict(gamma=1.5), ValueError),
        (dict(t=float("nan")), ValueError),
        (dict(t=-1.0), ValueError),
    ],
)
def test_bad_parameters(kwargs, exc):
    with pytest.raises(exc):
        detect_occlusions(np.zeros((3, 3), np.float32), **kwargs)


@pytest.mark.parametrize(
    ("disp", "exc"),
    [
        (np.zeros((3, 3), np.int16), TypeError),
        (np.zeros((3,), np.float32), ValueError),
        (np.zeros((0, 3), np.float32), ValueError),
        ([[1.0]], TypeError),
    ],
)
def test_bad_disparity(disp, exc):
    with pytest.raises(exc, match="disparity"):
        detect_occlusions(disp)


@pytest.mark.parametrize("d0", [0.75, 37.3, 1500.6])
@pytest.mark.parametrize(("lam", "gamma", "t"), [(2.0, 0.4375, 1.0), (0.3, 0.37, 0.1), (1.7, 0.9, 0.0)])
@pytest.mark.parametrize("window", [(9, 7), (3, 3), (5, 9), (9, 1)])  # each screen path of the kernel
def test_threshold_ties_match_reference(d0, lam, gamma, t, window):
    """Neighbours at exactly ``d + t + pen`` and a few float32 ulps around it.

    The kernel's float screen must never miss a cell that the exact (double) rule flags.
    """
    H, W = 9, 4000
    x0, y0 = 2600, 4
    d0 = np.float32(d0)
    offsets = [(1, 0), (-3, 2), (4, -3), (0, 1), (-4, 3), (-1, -1), (2, 4)]
    for dx, dy in [(dx, dy) for dx, dy in offsets if abs(dx) <= window[0] // 2 and abs(dy) <= window[1] // 2]:
        pen = lam * (gamma * abs(dx) + (1 - gamma) * abs(dy))
        base = np.float32(float(d0) + t + pen)
        for k in range(-3, 4):
            dn = base
            for _ in range(abs(k)):
                dn = np.nextafter(dn, np.float32(np.inf if k > 0 else -np.inf))
            disp = np.zeros((H, W), np.float32)
            disp[y0, x0] = d0
            xn = x0 - int(np.floor(float(d0) + 0.5)) + dx + int(np.floor(float(dn) + 0.5))
            disp[y0 + dy, xn] = dn
            occ = detect_occlusions(disp, window=window, lam=lam, gamma=gamma, t=t, threads=1)
            ref = ref_occlusions(disp, window=window, lam=lam, gamma=gamma, t=t)
            np.testing.assert_array_equal(occ, ref, err_msg=f"dx={dx} dy={dy} k={k}")
            assert ref[y0, x0] == ((float(dn) - float(d0)) - pen > t)
