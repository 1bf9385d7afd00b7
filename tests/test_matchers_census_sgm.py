"""Census-SGM kernels vs plain reference implementations (exact equality), on both builds of the kernels."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.census_sgm_reference import (
    ref_aggregate,
    ref_census,
    ref_hamming,
    ref_lr,
    ref_median,
    ref_right,
    ref_wta,
)
from vpp_service.matchers import census_sgm as cs

pytestmark = pytest.mark.usefixtures("census_build")


@pytest.fixture(params=[0, 1, 2])
def rng(request):
    return np.random.default_rng(request.param)


@pytest.mark.parametrize("shape", [(1, 1), (2, 3), (7, 9), (12, 31)])
def test_census_matches_reference(rng, shape):
    img = rng.integers(0, 256, shape).astype(np.uint8)
    img[0, 0] = img[-1, -1]  # some ties
    np.testing.assert_array_equal(cs.census_transform(img), ref_census(img))


def test_census_flat_image_is_zero():
    assert not cs.census_transform(np.full((6, 6), 77, np.uint8)).any()


@pytest.mark.parametrize("threads", [1, 2])
def test_hamming_matches_reference(rng, threads):
    cl = rng.integers(0, 1 << 24, (5, 13)).astype(np.uint32)
    cr = rng.integers(0, 1 << 24, (5, 13)).astype(np.uint32)
    np.testing.assert_array_equal(cs.hamming_cost_volume(cl, cr, 6, threads=threads), ref_hamming(cl, cr, 6))


def test_hamming_self_match_is_zero():
    c = np.random.default_rng(5).integers(0, 1 << 24, (3, 8)).astype(np.uint32)
    vol = cs.hamming_cost_volume(c, c, 4)
    assert not vol[:, :, 0].any()
    assert (vol[:, 0, 1:] == cs.INVALID_COST).all()  # x < d has no match


def test_p2_table_values():
    lut = cs.p2_table()
    assert lut.dtype == np.int16 and lut.shape == (256,)
    assert lut[0] == 35 and lut[1] == 34 and lut[2] == 34 and lut[3] == 33
    assert lut[36] == 17 and lut[255] == 17
    assert (cs.p2_table(p1=20, p2_min=5) >= 20).all()


@pytest.mark.parametrize("paths", [4, 8])
@pytest.mark.parametrize("cmax", [25, 300, 9000])
def test_aggregate_matches_literal_reference(rng, paths, cmax):
    C = rng.integers(0, cmax, (6, 7, 5)).astype(np.uint16)
    g = rng.integers(0, 256, (6, 7)).astype(np.uint8)
    g[2] = g[2, 0]  # flat row: P2 at its maximum
    got = cs.aggregate_costs(C, g, paths=paths)
    assert got.dtype == np.uint16 and got.shape == C.shape
    np.testing.assert_array_equal(got, ref_aggregate(C, g, paths, p1=11, p2min=17, alpha=0.5, gamma=35.0))


def test_aggregate_custom_penalties_and_threads(rng):
    C = rng.integers(0, 25, (5, 9, 4)).astype(np.uint16)
    g = rng.integers(0, 256, (5, 9)).astype(np.uint8)
    ref = ref_aggregate(C, g, 8, p1=3, p2min=9, alpha=1.25, gamma=60.0)
    for t in (1, 2):
        np.testing.assert_array_equal(
            cs.aggregate_costs(C, g, 8, p1=3, p2_min=9, alpha=1.25, gamma=60.0, threads=t), ref
        )


@pytest.mark.parametrize("uniqueness", [0.95, 0.7, 1.0])
@pytest.mark.parametrize("subpixel", [True, False])
@pytest.mark.parametrize("d", [7, 16, 20, 48])  # 16, 20 and 48: whole 16-disparity blocks and a part block
def test_wta_matches_reference(rng, uniqueness, subpixel, d):
    S = rng.integers(0, 40, (3, d + 20, d)).astype(np.uint16)  # small costs: many ties
    got = cs.select_disparity(S, uniqueness, subpixel)
    np.testing.assert_array_equal(got, ref_wta(S, uniqueness, subpixel))


@pytest.mark.parametrize("d", [5, 20, 32])
def test_wta_with_the_largest_cost_matches_reference(rng, d):
    # 65535 (NO_COST, the value of absent entries) as a real cost: the first minimum at the lowest d, and a
    # second minimum that equals the start value of the search
    S = np.where(rng.random((3, d + 20, d)) < 0.5, 65535, rng.integers(0, 4, (3, d + 20, d))).astype(np.uint16)
    S[:, ::7] = 65535  # whole pixels of it
    for uniqueness in (1.0, 0.95):
        np.testing.assert_array_equal(cs.select_disparity(S, uniqueness, True), ref_wta(S, uniqueness, True))


def test_wta_hand_cases():
    # columns 0..3 are the left band (fewer disparities); the hand cases sit at x >= D - 1 = 4
    band = np.full((1, 4, 5), 50, np.uint16)
    S = np.array([[[9, 4, 2, 6, 9], [5, 5, 5, 5, 5], [9, 1, 9, 9, 1]]], np.uint16)
    d = cs.select_disparity(np.ascontiguousarray(np.concatenate([band, S], 1)), 0.95, True)[:, 4:]
    assert d[0, 0] == pytest.approx(2 + (4 - 6) / (2 * (4 - 4 + 6)))
    assert np.isnan(d[0, 1])  # flat: not unique
    assert np.isnan(d[0, 2])  # two separated minima
    one = np.ascontiguousarray(np.concatenate([band, S[:, :1]], 1))
    assert cs.select_disparity(one, 0.95, False)[0, 4] == 2.0


def test_wta_left_band_uses_existing_disparities():
    # column x only has d <= x: the minimum at d = 4 is out of reach for x < 4; a minimum at d = x < D - 1
    # (x = 0, 1 here) is rejected: the cost may keep falling beyond the right image's edge
    S = np.tile(np.array([30, 20, 25, 40, 1], np.uint16), (1, 6, 1))
    d = cs.select_disparity(S, 1.0, False)
    np.testing.assert_array_equal(d[0], [np.nan, np.nan, 1, 1, 4, 4])
    assert cs.select_disparity(S, 1.0, True)[0, 2] == pytest.approx(1 + (30 - 25) / (2 * (30 - 40 + 25)))
    S[0, 1] = [10, 20, 0, 0, 0]  # x = 1: minimum at d = 0 < x, kept; d = 2 does not exist: no parabola
    assert cs.select_disparity(S, 1.0, True)[0, 1] == 0.0


def test_aggregate_marks_absent_disparities():
    C = np.random.default_rng(3).integers(0, 25, (3, 7, 5)).astype(np.uint16)
    S = cs.aggregate_costs(C, np.zeros((3, 7), np.uint8))
    for x in range(4):
        assert (S[:, x, x + 1 :] == cs.NO_COST).all()
        assert (S[:, x, : x + 1] < cs.NO_COST).all()
    assert (S[:, 4:] < cs.NO_COST).all()


def test_right_and_lr_check_match_reference(rng):
    S = rng.integers(0, 30, (5, 11, 4)).astype(np.uint16)
    dr = cs.right_disparity(S)
    np.testing.assert_array_equal(dr, ref_right(S))
    dl = cs.select_disparity(S, 1.0, True)
    for tol in (0.0, 0.5, 1.0):
        np.testing.assert_array_equal(cs.left_right_check(dl, dr, tol), ref_lr(dl, dr, tol))


@pytest.mark.parametrize("width", [5, 8, 45])  # the AVX2 build checks 8 pixels at once, then the rest
def test_lr_check_matches_reference_on_any_values(rng, width):
    H = 7
    x = np.arange(width)
    xr = rng.integers(0, width, (H, width))
    frac = rng.choice(np.float32([-0.5, -0.25, 0.0, 0.25, 0.5, 0.49]), (H, width))  # 0.5: the next x_r
    dl = (x - xr + frac).astype(np.float32)  # mostly inside the image, both signs
    pick = rng.random((H, width))
    dl[pick < 0.05] = np.nan
    big = (pick > 0.9) & (pick < 0.95)
    dl[big] = rng.choice(np.float32([3e6, -3e6, 2.0**21, -(2.0**21), 1e30, -1e30, 2.0**21 - 0.5]), big.sum())
    dr = np.full((H, width), np.nan, np.float32)
    dr[np.arange(H)[:, None], xr] = dl + rng.choice(np.float32([0.0, 0.25, -0.5, 1.0, -1.5, 3.0]), (H, width))
    dr[rng.random((H, width)) < 0.1] = np.nan
    dr[~np.isfinite(dr)] = np.where(rng.random(int((~np.isfinite(dr)).sum())) < 0.5, np.nan, 2.0)
    for tol in (0.0, 0.5, 1.0, 2.5):
        got = cs.left_right_check(dl, dr, tol)
        np.testing.assert_array_equal(got, ref_lr(dl, dr, tol))
        assert np.isfinite(got).sum() > 0


def test_median_matches_reference(rng):
    a = rng.normal(10, 3, (9, 11)).astype(np.float32)
    a[rng.random(a.shape) < 0.3] = np.nan
    np.testing.assert_array_equal(cs.median_filter3x3(a), ref_median(a))


def test_median_removes_isolated_outlier():
    a = np.full((5, 5), 7.0, np.float32)
    a[2, 2] = 90.0
    assert (cs.median_filter3x3(a) == 7.0).all()


@pytest.mark.parametrize(
    ("call", "exc", "match"),
    [
        (lambda: cs.census_transform(np.zeros((4, 4), np.float32)), TypeError, "gray"),
        (lambda: cs.census_transform(np.zeros((4, 4, 3), np.uint8)), ValueError, "gray"),
        (lambda: cs.census_transform(np.zeros((4, 8), np.uint8)[:, ::2]), ValueError, "contiguous"),
        (lambda: cs.census_transform(np.zeros((0, 4), np.uint8)), ValueError, "empty"),
        (
            lambda: cs.hamming_cost_volume(np.zeros((3, 4), np.uint32), np.zeros((3, 5), np.uint32), 2),
            ValueError,
            "same shape",
        ),
        (
            lambda: cs.hamming_cost_volume(np.zeros((3, 4), np.uint32), np.zeros((3, 4), np.uint32), 4),
            ValueError,
            "max_disparity",
        ),
        (
            lambda: cs.hamming_cost_volume(np.zeros((3, 4), np.uint32), np.zeros((3, 4), np.uint32), 0),
            ValueError,
            "max_disparity",
        ),
        (
            lambda: cs.hamming_cost_volume(np.zeros((3, 4), np.int32), np.zeros((3, 4), np.uint32), 2),
            TypeError,
            "census_left",
        ),
        (lambda: cs.aggregate_costs(np.zeros((3, 4, 2), np.float32), np.zeros((3, 4), np.uint8)), TypeError, "cost"),
        (lambda: cs.aggregate_costs(np.zeros((3, 4, 2), np.uint16), np.zeros((3, 5), np.uint8)), ValueError, "gray"),
        (
            lambda: cs.aggregate_costs(np.zeros((3, 4, 2), np.uint16), np.zeros((3, 4), np.uint8), paths=6),
            ValueError,
            "paths",
        ),
        (
            lambda: cs.aggregate_costs(np.zeros((3, 4, 2), np.uint16), np.zeros((3, 4), np.uint8), p1=-1),
            ValueError,
            "p1",
        ),
        (
            lambda: cs.aggregate_costs(np.zeros((3, 4, 2), np.uint16), np.zeros((3, 4), np.uint8), gamma=np.nan),
            ValueError,
            "gamma",
        ),
        (lambda: cs.select_disparity(np.zeros((3, 4, 2), np.uint16), uniqueness=0), ValueError, "uniqueness"),
        (lambda: cs.select_disparity(np.zeros((3, 4), np.uint16)), ValueError, "H x W x D"),
        (
            lambda: cs.left_right_check(np.zeros((3, 4), np.float32), np.zeros((3, 5), np.float32)),
            ValueError,
            "same shape",
        ),
        (
            lambda: cs.left_right_check(np.zeros((3, 4), np.float32), np.zeros((3, 4), np.float32), -1),
            ValueError,
            "tolerance",
        ),
        (lambda: cs.median_filter3x3(np.full((3, 4), np.inf, np.float32)), ValueError, "inf"),
        (lambda: cs.median_filter3x3(np.zeros((3, 4), np.float64)), TypeError, "float32"),
    ],
)
def test_kernel_bad_input(call, exc, match):
    with pytest.raises(exc, match=match):
        call()


@pytest.mark.parametrize(
    "opts",
    [
        {},
        {"border_margin": 0, "gap_size": 0},
        {"border_margin": 5, "gap_size": 1},
        {"lr_check": False, "median": False},
    ],
)
def test_matcher_chains_the_public_steps(rng, opts):
    """CensusSGM.compute == census -> Hamming -> SGM -> WTA -> LR -> border -> short gaps -> median -> speckles."""
    from vpp_service.matchers import build_matcher
    from vpp_service.matchers.border import reject_border_matches
    from vpp_service.matchers.holes import fill_short_gaps
    from vpp_service.matchers.speckle import remove_speckles

    tex = rng.integers(0, 256, (30, 70)).astype(np.uint8)
    left, right = np.ascontiguousarray(tex[:, 8:]), np.ascontiguousarray(tex[:, :-8])
    right[:, 20:24] = 128  # a flat stripe: rejected pixels and short gaps
    m = build_matcher("census-sgm", {"max_disparity": 16, **opts})
    o = m.options
    cost = cs.hamming_cost_volume(cs.census_transform(left), cs.census_transform(right), 16)
    agg = cs.aggregate_costs(cost, left)
    want = cs.select_disparity(agg, o.uniqueness, o.subpixel)
    if o.lr_check:
        want = cs.left_right_check(want, cs.right_disparity(agg), o.lr_tolerance)
    if o.border_margin:
        want = reject_border_matches(want, o.border_margin)
    if o.gap_size:
        want = fill_short_gaps(want, o.gap_size)
    if o.median:
        want = cs.median_filter3x3(want)
    want = remove_speckles(want, o.speckle_size, o.speckle_diff)
    got = m.compute(left, right)
    np.testing.assert_array_equal(got, want)
