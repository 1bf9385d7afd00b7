"""Tests of vpp_service.vpp.project: reference equality, hand-checkable cases, bad input, determinism."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from helpers.vpp import make_case
from vpp_reference import ref_project
from vpp_service.vpp import VPPConfig, backend, project
from vpp_service.vpp.rng import pattern_bytes


def sweep_cases(n: int = 44):
    rng = np.random.default_rng(1234)
    cases = []
    for i in range(n):
        pattern = ["random", "histogram"][i % 2]
        cfg = VPPConfig(
            pattern=pattern,
            patch=[1, 3, 5][(i // 2) % 3],
            uniform_patch=bool(rng.random() < 0.4),
            alpha=float(rng.choice([0.0, 0.2, 0.4, 1.0, float(rng.random())])),
            splat=bool(rng.random() < 0.75),
            occlusion=["fgd", "no", "bkgd", "off"][(i // 3) % 4],
            adaptive_patch=[None, None, "distance", "bilateral"][(i // 5) % 4],
            adaptive_max_disparity=None if rng.random() < 0.5 else float(rng.uniform(2, 20)),
            bilateral_sigma_color=float(rng.choice([2.0, 20.0])),
            search_width=int(rng.choice([64, 16, 7])),
            search_height=int(rng.choice([3, 1])),
            occ_t=float(rng.choice([1.0, 0.0, 3.0])),
        )
        shape = (int(rng.integers(6, 16)), int(rng.integers(12, 40)), int(rng.choice([1, 3])))
        cases.append((i, cfg, shape, float(rng.choice([0.05, 0.2, 0.5]))))
    return cases


@pytest.mark.parametrize(("i", "cfg", "shape", "density"), sweep_cases(), ids=lambda v: None)
def test_reference_equality(build, i, cfg, shape, density):
    rng = np.random.default_rng(i)
    left, right, disp = make_case(rng, *shape, density)
    l0, r0 = left.copy(), right.copy()
    res = project(left, right, disp, cfg, seed=i, threads=2)
    rl, rr, rocc = ref_project(left, right, disp, cfg, seed=i)
    assert np.array_equal(left, l0) and np.array_equal(right, r0), "inputs modified"
    assert res.left.shape == left.shape and res.left.dtype == np.uint8
    np.testing.assert_array_equal(res.occluded, rocc if cfg.occlusion != "off" else False)
    np.testing.assert_array_equal(res.right, rr)
    np.testing.assert_array_equal(res.left, rl)


@pytest.mark.parametrize(
    ("shape", "search"), [((12, 97, 3), (64, 3)), ((9, 70, 1), (16, 1)), ((7, 33, 3), (7, 3)), ((10, 131, 3), (100, 5))]
)
def test_histogram_tables_both_builders_match_reference(build, shape, search):
    """Wider than the 32-column blocks (full, partial last block), both builders."""
    rng = np.random.default_rng(shape[1])
    left, right, disp = make_case(rng, *shape, 0.1)
    cfg = VPPConfig(pattern="histogram", search_width=search[0], search_height=search[1])
    res = project(left, right, disp, cfg, seed=1, threads=2)
    rl, rr, _ = ref_project(left, right, disp, cfg, seed=1)
    np.testing.assert_array_equal(res.right, rr)
    np.testing.assert_array_equal(res.left, rl)


def test_histogram_all_bins_filled_matches_reference():
    rng = np.random.default_rng(7)
    left = rng.integers(0, 256, (9, 140), dtype=np.uint8)
    right = rng.integers(0, 256, (9, 140), dtype=np.uint8)
    disp = np.zeros((9, 140), np.float32)
    disp[4, 60:80:5] = [3.0, 10.5, 20.25, 7.0]
    cfg = VPPConfig(pattern="histogram", patch=3, search_width=128, search_height=3, occlusion="off", alpha=1.0)
    res = project(left, right, disp, cfg)
    rl, rr, _ = ref_project(left, right, disp, cfg)
    np.testing.assert_array_equal(res.left, rl)
    np.testing.assert_array_equal(res.right, rr)


# ------------------------------------------------------------ hand-checkable
@pytest.fixture
def gray_pair():
    left = np.full((9, 30), 100, np.uint8)
    right = np.full((9, 30), 100, np.uint8)
    return left, right


def test_alpha_one_pointwise_integer_disparity_same_values():
    rng = np.random.default_rng(0)
    left = rng.integers(0, 256, (20, 50, 3), dtype=np.uint8)
    right = rng.integers(0, 256, (20, 50, 3), dtype=np.uint8)
    disp = np.zeros((20, 50), np.float32)
    ys, xs = rng.integers(0, 20, 30), rng.integers(20, 50, 30)
    ds = rng.integers(1, 20, 30).astype(np.float32)
    disp[ys, xs] = ds
    cfg = VPPConfig(patch=1, alpha=1.0, occlusion="off")
    res = project(left, right, disp, cfg, seed=5)
    for y, x in zip(*np.nonzero(disp), strict=True):
        d = int(disp[y, x])
        np.testing.assert_array_equal(res.left[y, x], res.right[y, x - d])
        np.testing.assert_array_equal(res.left[y, x], pattern_bytes(5, x, y, 3))


def test_splat_weights_at_d_5_25(gray_pair):
    left, right = gray_pair
    left = np.full((9, 30, 3), 0, np.uint8)
    right = np.full((9, 30, 3), 0, np.uint8)
    disp = np.zeros((9, 30), np.float32)
    disp[4, 20] = 5.25  # x' = 14.75: col 14 gets 0.25, col 15 gets 0.75
    res = project(left, right, disp, VPPConfig(patch=1, alpha=1.0, occlusion="off"), seed=3)
    a = pattern_bytes(3, 20, 4, 3).astype(np.float64)
    np.testing.assert_array_equal(res.left[4, 20], a.astype(np.uint8))
    np.testing.assert_array_equal(res.right[4, 14], np.floor(a * 0.25 + 0.5).astype(np.uint8))
    np.testing.assert_array_equal(res.right[4, 15], np.floor(a * 0.75 + 0.5).astype(np.uint8))
    changed = np.argwhere((res.right != 0).any(axis=2))
    assert {tuple(p) for p in changed} <= {(4, 14), (4, 15)}


def test_alpha_zero_changes_nothing():
    rng = np.random.default_rng(1)
    left = rng.integers(0, 256, (15, 40, 3), dtype=np.uint8)
    right = rng.integers(0, 256, (15, 40, 3), dtype=np.uint8)
    disp = np.where(rng.random((15, 40)) < 0.3, rng.uniform(0.5, 20, (15, 40)), 0).astype(np.float32)
    for occ in ("fgd", "bkgd"):
        res = project(left, right, disp, VPPConfig(alpha=0.0, occlusion=occ))
        np.testing.assert_array_equal(res.left, left)
        np.testing.assert_array_equal(res.right, right)


def test_histogram_flat_gray_picks_255(gray_pair):
    left, right = gray_pair
    disp = np.zeros(left.shape, np.float32)
    disp[4, 15] = 4.0
    res = project(left, right, disp, VPPConfig(pattern="histogram", patch=1, alpha=1.0, occlusion="off"))
    assert res.left[4, 15] == 255 and res.right[4, 11] == 255


def test_histogram_picks_widest_gap_centre():
    left = np.zeros((3, 64), np.uint8)
    left[:, ::2] = 255  # bins 0 and 255 filled: centre 127
    right = left.copy()
    disp = np.zeros((3, 64), np.float32)
    disp[1, 30] = 2.0
    res = project(left, right, disp, VPPConfig(pattern="histogram", patch=1, alpha=1.0, occlusion="off"))
    assert res.left[1, 30] == 127


def test_collision_is_occluded_and_fgd_copies_right_content():
    H, W = 11, 60
    left = np.full((H, W), 50, np.uint8)
    right = np.full((H, W), 50, np.uint8)
    right[:, 20:24] = 200  # foreground texture in R
    disp = np.zeros((H, W), np.float32)
    disp[5, 30] = 8.0  # background: x' = 22
    disp[5, 40] = 18.0  # foreground: x' = 22, same cell, larger d
    occ_cfg = VPPConfig(patch=1, alpha=1.0, occlusion="fgd")
    res = project(left, right, disp, occ_cfg)
    assert res.occluded[5, 30] and not res.occluded[5, 40]
    assert res.stats.occluded == 1 and res.stats.projected == 1
    # the occluded background pixel took the (final, painted) right content at x' = 22
    assert res.left[5, 30] == res.right[5, 22]
    # with "no" it is untouched
    res_no = project(left, right, disp, VPPConfig(patch=1, alpha=1.0, occlusion="no"))
    assert res_no.left[5, 30] == 50


def test_left_border_point_still_paints_left():
    left = np.zeros((7, 30, 3), np.uint8)
    right = np.zeros((7, 30, 3), np.uint8)
    disp = np.zeros((7, 30), np.float32)
    disp[3, 2] = 6.5  # x' = -4.5
    res = project(left, right, disp, VPPConfig(alpha=1.0, occlusion="fgd"), seed=9)
    assert res.stats.out_of_bounds == 1 and res.stats.projected == 1
    assert (res.left[2:5, 1:4] != 0).any()
    assert not res.right.any()


def test_stats_counts_invalid_points():
    left = np.zeros((5, 10), np.uint8)
    disp = np.zeros((5, 10), np.float32)
    disp[0, :5] = [-1.0, np.inf, -np.inf, 10.0, 3.0]
    disp[1, 0] = np.nan
    res = project(left, left, disp)
    assert res.stats.given == 5 and res.stats.invalid == 4
    assert res.stats.projected == 1 and res.stats.out_of_bounds == 0


def test_float64_disparity_is_accepted_and_converted():
    rng = np.random.default_rng(3)
    left = rng.integers(0, 256, (8, 20, 3), dtype=np.uint8)
    disp = np.where(rng.random((8, 20)) < 0.3, rng.uniform(0.5, 9, (8, 20)), 0.0)
    a = project(left, left, disp)
    b = project(left, left, disp.astype(np.float32))
    np.testing.assert_array_equal(a.left, b.left)
    np.testing.assert_array_equal(a.right, b.right)


def test_non_contiguous_inputs_are_copied():
    rng = np.random.default_rng(4)
    big = rng.integers(0, 256, (10, 60, 3), dtype=np.uint8)
    disp = np.where(rng.random((10, 60)) < 0.3, rng.uniform(0.5, 9, (10, 60)), 0).astype(np.float32)
    a = project(big[:, ::2], big[:, 1::2], disp[:, ::2])
    b = project(big[:, ::2].copy(), big[:, 1::2].copy(), disp[:, ::2].copy())
    np.testing.assert_array_equal(a.left, b.left)
    np.testing.assert_array_equal(a.right, b.right)


def test_patch_larger_than_image():
    left = np.full((2, 3), 10, np.uint8)
    disp = np.zeros((2, 3), np.float32)
    disp[1, 2] = 1.5
    cfg = VPPConfig(patch=9, alpha=1.0)
    res = project(left, left, disp, cfg)
    rl, rr, _ = ref_project(left, left, disp, cfg)
    np.testing.assert_array_equal(res.left, rl)
    np.testing.assert_array_equal(res.right, rr)


# ------------------------------------------------------------ bad input
@pytest.mark.parametrize(
    ("kwargs", "exc", "word"),
    [
        (dict(left=np.zeros((4, 5), np.uint16)), TypeError, "left"),
        (dict(right=np.zeros((4, 6), np.uint8)), ValueError, "shape"),
        (dict(left=np.zeros((4, 5, 2), np.uint8), right=np.zeros((4, 5, 2), np.uint8)), ValueError, "left"),
        (dict(left=np.zeros((0, 5), np.uint8), right=np.zeros((0, 5), np.uint8)), ValueError, "left"),
        (dict(disparity=np.zeros((4, 5), np.int32)), TypeError, "disparity"),
        (dict(disparity=np.zeros((4, 6), np.float32)), ValueError, "disparity"),
        (dict(disparity=[[0.0]]), TypeError, "disparity"),
        (dict(left="x"), TypeError, "left"),
        (dict(config={"patch": 3}), TypeError, "config"),
        (dict(seed=-1), ValueError, "seed"),
        (dict(seed=1.5), TypeError, "seed"),
        (dict(threads=0), ValueError, "threads"),
    ],
)
def test_bad_input(kwargs, exc, word):
    args = dict(
        left=np.zeros((4, 5), np.uint8), right=np.zeros((4, 5), np.uint8), disparity=np.zeros((4, 5), np.float32)
    )
    args.update(kwargs)
    extra = {k: args.pop(k) for k in ("config", "seed", "threads") if k in args}
    with pytest.raises(exc, match=word):
        project(
            args["left"],
            args["right"],
            args["disparity"],
            *([extra.pop("config")] if "config" in extra else []),
            **extra,
        )


# ------------------------------------------------------------ determinism
@pytest.fixture(scope="module")
def det_case():
    rng = np.random.default_rng(11)
    left = rng.integers(0, 256, (120, 160, 3), dtype=np.uint8)
    right = rng.integers(0, 256, (120, 160, 3), dtype=np.uint8)
    disp = np.where(rng.random((120, 160)) < 0.2, rng.uniform(0.5, 60, (120, 160)), 0).astype(np.float32)
    return left, right, disp


@pytest.mark.parametrize(
    "cfg",
    [
        VPPConfig(),
        VPPConfig(pattern="histogram"),
        VPPConfig(pattern="histogram", uniform_patch=True, patch=5),
        VPPConfig(adaptive_patch="distance", patch=5),
    ],
)
def test_thread_count_does_not_change_bytes(det_case, cfg):
    left, right, disp = det_case
    a = project(left, right, disp, cfg, seed=3, threads=1)
    b = project(left, right, disp, cfg, seed=3, threads=2)
    c = project(left, right, disp, cfg, seed=3, threads=3)
    for x, y in ((a, b), (a, c)):
        assert x.left.tobytes() == y.left.tobytes() and x.right.tobytes() == y.right.tobytes()
        np.testing.assert_array_equal(x.occluded, y.occluded)


def test_seed_controls_random_pattern(det_case):
    left, right, disp = det_case
    a = project(left, right, disp, seed=1)
    b = project(left, right, disp, seed=1)
    c = project(left, right, disp, seed=2)
    assert a.left.tobytes() == b.left.tobytes()
    assert a.left.tobytes() != c.left.tobytes()


# ------------------------------------------------------------ fuzz
@settings(max_examples=60, deadline=None)
@given(
    H=st.integers(1, 12),
    W=st.integers(1, 40),
    C=st.sampled_from([0, 1, 3]),
    patch=st.sampled_from([1, 3, 5, 7]),
    pattern=st.sampled_from(["random", "histogram"]),
    occ=st.sampled_from(["fgd", "no", "bkgd", "off"]),
    adaptive=st.sampled_from([None, "distance", "bilateral"]),
    uniform=st.booleans(),
    splat=st.booleans(),
    seed=st.integers(0, 2**64 - 1),
    data=st.data(),
)
def test_fuzz_no_crash(H, W, C, patch, pattern, occ, adaptive, uniform, splat, seed, data):
    shape = (H, W) if C == 0 else (H, W, C)
    vals = st.sampled_from(
        [
            0.0,
            0.0,
            0.0,
            -1.0,
            0.5,
            1.0,
            2.5,
            7.25,
            1e30,
            float("nan"),
            float("inf"),
            float(W),
            float(W) - 0.01,
            3.0,
            11.9,
        ]
    )
    flat = data.draw(st.lists(vals, min_size=H * W, max_size=H * W))
    disp = np.array(flat, np.float32).reshape(H, W)
    rng = np.random.default_rng(seed % 1000)
    left = rng.integers(0, 256, shape, dtype=np.uint8)
    right = rng.integers(0, 256, shape, dtype=np.uint8)
    cfg = VPPConfig(
        patch=patch, pattern=pattern, occlusion=occ, adaptive_patch=adaptive, uniform_patch=uniform, splat=splat
    )
    res = project(left, right, disp, cfg, seed=seed)
    assert res.left.shape == shape and res.right.shape == shape
    s = res.stats
    assert s.given == s.invalid + int(((disp > 0) & (disp < W)).sum())


# ---------------------------------------------------------------- bit-parallel histogram pick
def _occupancies(seed: int, n: int):
    rng = np.random.default_rng(seed)
    for it in range(n):
        mode = it % 5
        if mode == 0:
            occ = rng.random(256) < rng.random()
        elif mode == 1:
            occ = rng.random(256) < 0.9
        elif mode == 2:
            occ = np.zeros(256, bool)
            occ[rng.integers(0, 256, rng.integers(1, 6))] = True
        elif mode == 3:
            occ = rng.random(256) < 0.995
        else:
            occ = np.ones(256, bool)
            s = rng.integers(0, 256)
            occ[s : s + rng.integers(0, 200)] = False
        yield occ


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_hist_pick_bits_matches_reference(build, seed):
    from vpp_reference import hist_pick

    edge = [np.zeros(256, bool), np.ones(256, bool)]
    for k in (0, 1, 63, 64, 127, 128, 191, 192, 255):
        one = np.zeros(256, bool)
        one[k] = True
        edge += [one, ~one]
    for occ in list(_occupancies(seed, 3000)) + edge:
        bits = np.ascontiguousarray(np.packbits(occ, bitorder="little").view(np.uint64))
        ref = -1 if occ.all() else hist_pick(occ.astype(np.int64))
        assert build.hist_pick_bits(bits) == ref, np.nonzero(~occ)[0]


def test_hist_pick_bits_rejects_bad_length():
    with pytest.raises(ValueError, match="occupancy"):
        backend.sweep.hist_pick_bits(np.zeros(3, np.uint64))
