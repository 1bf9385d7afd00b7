"""Per-pixel confidence: census-SGM's kernel vs the plain reference, the two-pass left-right check, min_confidence.

The census-SGM confidence must equal :func:`helpers.census_sgm_reference.ref_confidence` exactly on both
builds of the kernels (the keyed WTA of the AVX2 build included), and asking for it must leave the
disparity byte for byte as it was.
"""

from __future__ import annotations

import numpy as np
import pytest

from helpers.census_sgm_reference import ref_aggregate, ref_census, ref_confidence, ref_hamming, ref_match
from helpers.frames import noisy_shifted_pair
from vpp_service.matchers import build_matcher
from vpp_service.matchers.confidence import LR_SPAN, apply_min_confidence, lr_confidence, right_view
from vpp_service.matchers.guided import modulate_cost

H, W, D = 12, 40, 16
SHIFT = 5


def pair(seed: int, h: int = H, w: int = W, shift: int = SHIFT) -> tuple[np.ndarray, np.ndarray]:
    return noisy_shifted_pair(seed, h, w, shift)


def ref_volume(left: np.ndarray, right: np.ndarray, d: int, **opts: float) -> np.ndarray:
    o = {"p1": 11, "p2min": 17, "alpha": 0.5, "gamma": 35.0, **opts}
    cost = ref_hamming(ref_census(left), ref_census(right), d)
    return ref_aggregate(cost, left, 8, p1=o["p1"], p2min=o["p2min"], alpha=o["alpha"], gamma=o["gamma"])


@pytest.mark.usefixtures("census_build")
@pytest.mark.parametrize("threads", [1, 2])
@pytest.mark.parametrize(
    ("d", "opts", "ref_opts"),
    [
        (D, {}, {}),  # narrow sums; the AVX2 build: keyed WTA
        (D, {"lr_check": False, "median": False}, {}),  # the right WTA runs for the confidence alone
        (D, {"p2_gamma": 40.0}, {"gamma": 40.0}),  # uint16 partial sums: the plain WTA on both builds
        (D, {"confidence_peak": 0.25, "lr_tolerance": 2.0}, {}),
        (20, {}, {}),  # part of a 16-disparity block of keys
        (48, {}, {}),  # the AVX2 build's byte path costs, a left band wider than a block
    ],
)
def test_census_sgm_confidence_equals_reference(threads, d, opts, ref_opts):
    left, right = pair(3, 10, d + 30, 7)
    right[:, 12:16] = 128  # a flat stripe: ties, rejected pixels, low peaks
    o = {"max_disparity": d, "threads": threads, "speckle_size": 0, **opts}
    m = build_matcher("census-sgm", o)
    disp, conf = m.compute_with_confidence(left, right)
    np.testing.assert_array_equal(disp, m.compute(left, right))  # the disparity does not change
    if "lr_tolerance" not in opts:  # (the reference chain checks with tolerance 1)
        want_disp = ref_match(left, right, d, **{k: v for k, v in opts.items() if k != "confidence_peak"})
        np.testing.assert_array_equal(disp, want_disp)
    want = ref_confidence(ref_volume(left, right, d, **ref_opts), m.options.confidence_peak, m.options.lr_tolerance)
    want[np.isnan(disp)] = 0.0  # no answer, no confidence
    np.testing.assert_array_equal(conf, want)
    assert conf.dtype == np.float32 and conf.min() >= 0 and conf.max() <= 1
    assert 0 < np.mean(conf[np.isfinite(disp)] >= 0.5) < 1  # both sides of the threshold occur


@pytest.mark.usefixtures("census_build")
def test_census_sgm_guided_confidence_equals_reference():
    """Hints: the cost volume path (uint16 sums) gives the confidence of the modulated costs."""
    left, right = pair(4)
    hints = np.full((H, W), np.nan, np.float32)
    hints[::3, ::4] = SHIFT
    m = build_matcher("census-sgm", {"max_disparity": D, "threads": 1, "speckle_size": 0})
    disp, conf = m.compute_with_confidence(left, right, hints=hints)
    np.testing.assert_array_equal(disp, m.compute(left, right, hints=hints))
    cost = modulate_cost(ref_hamming(ref_census(left), ref_census(right), D), hints, 10.0, 1.0)
    want = ref_confidence(ref_aggregate(cost, left, 8, p1=11, p2min=17, alpha=0.5, gamma=35.0), 1.0)
    want[np.isnan(disp)] = 0.0
    np.testing.assert_array_equal(conf, want)


def test_lr_confidence_values():
    dl = np.array([[np.nan, 1.0, 1.0, 2.0, 0.4, 3.0]], np.float32)
    dr = np.array([[1.0, 1.0, 2.0, 0.0, 0.5, np.nan]], np.float32)
    # x=1: xr=0, dr=1 -> 1; x=2: xr=1, dr=1 -> 1; x=3: xr=1 -> |2-1| = 1 -> 0.5; x=4: xr=4 (0.4 rounds to 0),
    # dr=0.5 -> 1 - 0.1/2; x=5: xr=2, dr=2 -> 1 - 1/2.  x=0: NaN -> 0.
    want = np.array([[0.0, 1.0, 1.0, 0.5, 1 - 0.1 / LR_SPAN, 0.5]], np.float32)
    np.testing.assert_allclose(lr_confidence(dl, dr), want, rtol=0, atol=1e-6)
    out = np.array([[5.0, 7.0]], np.float32)  # right pixel outside the image: 0
    assert lr_confidence(out, np.zeros_like(out)).tolist() == [[0.0, 0.0]]
    with pytest.raises(ValueError, match="span"):
        lr_confidence(dl, dr, 0.0)


def test_right_view_of_a_shifted_pair_is_its_disparity():
    """SGBM on the mirrored pair: the right view of a constant shift has that disparity."""
    left, right = pair(5, 60, 160, 9)
    m = build_matcher("sgbm", {"max_disparity": 32})
    dr = right_view(m.compute, left, right)
    inner = dr[5:-5, 10 : 160 - 40]
    assert np.nanmedian(inner) == pytest.approx(9, abs=0.25)
    assert np.mean(np.abs(inner - 9) <= 1) > 0.9


@pytest.mark.parametrize("name", ["sgbm", "bm"])
def test_two_pass_confidence_marks_the_occlusion(name):
    """A box in front of a plane: the second pass finds the wrong answers (at the occlusion beside the box)."""
    from test_matchers_accuracy import make_scene

    left, right, gt, _ = make_scene(h=96, w=192)
    m = build_matcher(name, {"max_disparity": 32})
    disp, conf = m.compute_with_confidence(left, right)
    np.testing.assert_array_equal(disp, m.compute(left, right))
    assert conf.shape == disp.shape and conf.dtype == np.float32
    assert np.all(conf[np.isnan(disp)] == 0)
    answered = np.isfinite(disp)
    bad = answered & ~(np.abs(disp - gt) <= 2)
    # the unconfident pixels are wrong far more often than the confident ones, which are most of them
    sure = answered & (conf >= 0.5)
    assert bad[answered & ~sure].mean() > 5 * bad[sure].mean()
    assert sure.sum() > 0.8 * answered.sum()


def test_min_confidence_makes_holes_then_fill():
    left, right = pair(6, 40, 120, 6)
    right[:, 40:52] = 100
    plain = build_matcher("census-sgm", {"max_disparity": D, "speckle_size": 0})
    disp, conf = plain.compute_with_confidence(left, right)
    strict = build_matcher("census-sgm", {"max_disparity": D, "speckle_size": 0, "min_confidence": 0.5})
    held = strict.compute(left, right)
    want = np.where(conf >= 0.5, disp, np.nan)
    np.testing.assert_array_equal(held, want)
    assert np.isnan(held).sum() > np.isnan(disp).sum()  # some low-confidence pixels became holes
    d2, c2 = strict.compute_with_confidence(left, right)
    np.testing.assert_array_equal(d2, want)
    assert np.all(c2[np.isnan(d2)] == 0) and np.all(c2[np.isfinite(d2)] >= 0.5)
    filled = build_matcher("census-sgm", {"max_disparity": D, "speckle_size": 0, "min_confidence": 0.5, "fill": True})
    d3, c3 = filled.compute_with_confidence(left, right)
    assert np.isfinite(d3).all()
    np.testing.assert_array_equal(c3, c2)  # the filled pixels keep confidence 0


def test_apply_min_confidence_in_place_and_readonly():
    disp = np.array([[1.0, np.nan, 3.0]], np.float32)
    conf = np.array([[0.2, 0.9, 0.8]], np.float32)
    out = apply_min_confidence(disp, conf, 0.5)
    assert out is disp and np.isnan(out[0, 0]) and out[0, 2] == 3.0
    assert conf.tolist() == [[0.0, 0.0, pytest.approx(0.8)]]
    ro = np.array([[1.0, 2.0]], np.float32)
    ro.setflags(write=False)
    c = np.array([[0.1, 0.6]], np.float32)
    got = apply_min_confidence(ro, c, 0.5)
    assert got is not ro and np.isnan(got[0, 0]) and ro[0, 0] == 1.0


@pytest.mark.parametrize("bad", [-0.1, 1.5, float("nan"), True, "0.5"])
def test_min_confidence_option_is_checked(bad):
    with pytest.raises(ValueError, match="min_confidence"):
        build_matcher("census-sgm", {"min_confidence": bad})


@pytest.mark.parametrize("bad", [0.0, -1.0, 1.5, float("inf")])
def test_confidence_peak_option_is_checked(bad):
    with pytest.raises(ValueError, match="confidence_peak"):
        build_matcher("census-sgm", {"confidence_peak": bad})
