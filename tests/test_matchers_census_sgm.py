"""Census-SGM kernels vs plain reference implementations (exact equality)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vpp_service.matchers import census_sgm as cs

OFFSETS = [(dy, dx) for dy in range(-2, 3) for dx in range(-2, 3) if (dy, dx) != (0, 0)]


def ref_census(img: np.ndarray) -> np.ndarray:
    h, w = img.shape
    pad = np.pad(img, 2, mode="edge").astype(np.int32)
    code = np.zeros((h, w), np.uint32)
    for dy, dx in OFFSETS:
        nb = pad[2 + dy : 2 + dy + h, 2 + dx : 2 + dx + w]
        code = (code << np.uint32(1)) | (nb < img).astype(np.uint32)
    return code


def ref_hamming(cl: np.ndarray, cr: np.ndarray, D: int) -> np.ndarray:
    h, w = cl.shape
    out = np.full((h, w, D), cs.INVALID_COST, np.uint16)
    for d in range(D):
        x = np.bitwise_xor(cl[:, d:], cr[:, : w - d])
        out[:, d:, d] = np.array([int(v).bit_count() for v in x.ravel()]).reshape(x.shape)
    return out


def ref_aggregate(C, g, paths, p1, p2min, alpha, gamma):
    H, W, D = C.shape
    C = np.minimum(C.astype(np.int64), cs.COST_CAP)
    dirs = [(0, 1), (0, -1), (1, 0), (-1, 0)]
    if paths == 8:
        dirs += [(1, 1), (1, -1), (-1, 1), (-1, -1)]
    S = np.zeros((H, W, D), np.int64)
    for dy, dx in dirs:
        L = np.zeros((H, W, D), np.int64)
        for y in range(H) if dy >= 0 else range(H - 1, -1, -1):
            for x in range(W) if dx >= 0 else range(W - 1, -1, -1):
                py, px = y - dy, x - dx
                if not (0 <= py < H and 0 <= px < W):
                    L[y, x] = C[y, x]
                    continue
                prev = L[py, px]
                m = prev.min()
                step = abs(int(g[y, x]) - int(g[py, px]))
                p2 = max(p2min, p1, math.floor(gamma - alpha * step))
                for d in range(D):
                    v = min(prev[d], m + p2)
                    if d > 0:
                        v = min(v, prev[d - 1] + p1)
                    if d < D - 1:
                        v = min(v, prev[d + 1] + p1)
                    L[y, x, d] = C[y, x, d] + v - m
        S += L
    return S


def ref_wta(S, uniqueness, subpixel):
    H, W, D = S.shape
    out = np.full((H, W), np.nan, np.float32)
    for y in range(H):
        for x in range(W):
            c = [int(v) for v in S[y, x]]
            best = int(np.argmin(c))
            others = [c[d] for d in range(D) if abs(d - best) > 1]
            if others and not c[best] < uniqueness * min(others):
                continue
            val = float(best)
            if subpixel and 0 < best < D - 1:
                den = c[best - 1] - 2 * c[best] + c[best + 1]
                if den > 0:
                    val = best + (c[best - 1] - c[best + 1]) / (2.0 * den)
            out[y, x] = val
    return out


def ref_right(S):
    H, W, D = S.shape
    out = np.zeros((H, W), np.float32)
    for y in range(H):
        for xr in range(W):
            c = [S[y, xr + d, d] for d in range(D) if xr + d < W]
            out[y, xr] = int(np.argmin(c))
    return out


def ref_lr(dl, dr, tol):
    out = np.full_like(dl, np.nan)
    H, W = dl.shape
    for y in range(H):
        for x in range(W):
            d = dl[y, x]
            if np.isnan(d):
                continue
            xr = x - math.floor(float(d) + 0.5)
            if 0 <= xr < W and not np.isnan(dr[y, xr]) and abs(float(d) - float(dr[y, xr])) <= tol:
                out[y, x] = d
    return out


def ref_median(a):
    H, W = a.shape
    out = np.full_like(a, np.nan)
    for y in range(H):
        for x in range(W):
            if np.isnan(a[y, x]):
                continue
            win = a[max(0, y - 1) : y + 2, max(0, x - 1) : x + 2]
            out[y, x] = np.median(win[~np.isnan(win)])
    return out


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
    np.testing.assert_array_equal(got, ref_aggregate(C, g, paths, 11, 17, 0.5, 35.0))


def test_aggregate_custom_penalties_and_threads(rng):
    C = rng.integers(0, 25, (5, 9, 4)).astype(np.uint16)
    g = rng.integers(0, 256, (5, 9)).astype(np.uint8)
    ref = ref_aggregate(C, g, 8, 3, 9, 1.25, 60.0)
    for t in (1, 2):
        np.testing.assert_array_equal(
            cs.aggregate_costs(C, g, 8, p1=3, p2_min=9, alpha=1.25, gamma=60.0, threads=t), ref
        )


@pytest.mark.parametrize("uniqueness", [0.95, 0.7, 1.0])
@pytest.mark.parametrize("subpixel", [True, False])
def test_wta_matches_reference(rng, uniqueness, subpixel):
    S = rng.integers(0, 40, (6, 8, 7)).astype(np.uint16)
    got = cs.select_disparity(S, uniqueness, subpixel)
    np.testing.assert_array_equal(got, ref_wta(S, uniqueness, subpixel))


def test_wta_hand_cases():
    S = np.array([[[9, 4, 2, 6, 9], [5, 5, 5, 5, 5], [9, 1, 9, 9, 1]]], np.uint16)
    d = cs.select_disparity(S, 0.95, True)
    assert d[0, 0] == pytest.approx(2 + (4 - 6) / (2 * (4 - 4 + 6)))
    assert np.isnan(d[0, 1])  # flat: not unique
    assert np.isnan(d[0, 2])  # two separated minima
    assert cs.select_disparity(S[:, :1], 0.95, False)[0, 0] == 2.0


def test_right_and_lr_check_match_reference(rng):
    S = rng.integers(0, 30, (5, 11, 4)).astype(np.uint16)
    dr = cs.right_disparity(S)
    np.testing.assert_array_equal(dr, ref_right(S))
    dl = cs.select_disparity(S, 1.0, True)
    for tol in (0.0, 0.5, 1.0):
        np.testing.assert_array_equal(cs.left_right_check(dl, dr, tol), ref_lr(dl, dr, tol))


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
