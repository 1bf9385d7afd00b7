"""The sweep kernel (vpp_service/vpp/_sweep.pyx) against the literal reference, on both builds.

These cases are larger than test_vpp_project's sweep so that rows split into
several chunks per thread, spans reach the 16-byte SIMD paths and the fallbacks
(wide patches, row ends, left-border matches), and maps use NaN as "no point".
"""

from __future__ import annotations

import numpy as np
import pytest

from helpers.vpp import BUILDS, make_case
from vpp_reference import ref_occlusions, ref_project
from vpp_service.vpp import VPPConfig, backend, detect_occlusions, project


def test_builds_report_themselves():
    assert backend.portable.AVX2 is False
    if BUILDS["avx2"] is not None:
        assert BUILDS["avx2"].AVX2 is True
    assert backend.sweep in [m for m in BUILDS.values() if m is not None]


CASES = [
    # (patch, C, splat, occlusion, alpha, window (x, y), t, shape (H, W), density)
    (3, 3, True, "fgd", 0.4, (9, 7), 1.0, (41, 97), 0.05),  # the default, several chunks
    (3, 1, True, "fgd", 0.4, (9, 7), 1.0, (37, 80), 0.10),
    (1, 3, True, "no", 0.7, (9, 7), 1.0, (30, 64), 0.20),
    (5, 3, True, "bkgd", 0.4, (9, 7), 0.0, (33, 90), 0.08),  # (K+1)*C > 16: two-span path
    (5, 1, False, "fgd", 1.0, (3, 3), 1.0, (29, 70), 0.10),
    (7, 3, True, "off", 0.2, (9, 7), 1.0, (26, 60), 0.05),
    (9, 1, True, "fgd", 0.5, (15, 11), 3.0, (45, 75), 0.04),
    (3, 3, False, "no", 0.4, (1, 1), 1.0, (21, 50), 0.30),
    (3, 3, True, "fgd", 0.0, (9, 7), 1.0, (24, 48), 0.10),  # alpha 0: nothing changes
    (3, 3, True, "fgd", 1.0, (5, 9), 0.5, (38, 66), 0.15),  # alpha 1: w = 65536
]


def case_arrays(i, shape, C, density, nan_background):
    rng = np.random.default_rng(100 + i)
    left, right, disp = make_case(rng, shape[0], shape[1], C, density)
    if C == 1 and left.ndim == 3:
        left, right = left[:, :, 0], right[:, :, 0]
    if nan_background:
        disp[disp == 0] = np.nan
    return left, right, disp


@pytest.mark.parametrize("i", range(len(CASES)))
@pytest.mark.parametrize("nan_background", [False, True])
def test_sweep_matches_reference(build, i, nan_background):
    patch, C, splat, occ, alpha, window, t, shape, density = CASES[i]
    cfg = VPPConfig(
        patch=patch, splat=splat, occlusion=occ, alpha=alpha, occ_window_x=window[0], occ_window_y=window[1], occ_t=t
    )
    left, right, disp = case_arrays(i, shape, C, density, nan_background)
    rl, rr, rocc = ref_project(left, right, np.nan_to_num(disp, nan=0.0), cfg, seed=i)
    for nt in (1, 2, 3):
        res = project(left, right, disp, cfg, seed=i, threads=nt)
        np.testing.assert_array_equal(res.occluded, rocc if occ != "off" else False)
        np.testing.assert_array_equal(res.right, rr, err_msg=f"right, {nt} threads")
        np.testing.assert_array_equal(res.left, rl, err_msg=f"left, {nt} threads")
        assert res.stats.occluded == (int(rocc.sum()) if occ != "off" else 0)
        assert res.stats.to_dict() == expected_stats(disp, res.stats.occluded, occ)


def expected_stats(disp, occluded, occ):
    """Point counts computed with NumPy from the map (the module docstring's rules)."""
    with np.errstate(invalid="ignore"):
        given = (disp != 0) & ~np.isnan(disp)
        valid = given & (disp > 0) & (disp < disp.shape[1])
        oob = valid & (np.arange(disp.shape[1])[None, :] - disp.astype(np.float64) < 0)
    n_valid = int(valid.sum())
    return {
        "given": int(given.sum()),
        "invalid": int(given.sum()) - n_valid,
        "out_of_bounds": int(oob.sum()),
        "occluded": occluded,
        "projected": n_valid - occluded if occ in ("no", "fgd") else n_valid,
    }


@pytest.mark.parametrize(
    ("window", "lam", "gamma", "t"),
    [((9, 7), 2.0, 0.4375, 1.0), ((3, 5), 0.0, 1.0, 0.0), ((21, 1), 1.3, 0.1, 2.5), ((1, 13), 5.0, 0.9, 0.25)],
)
def test_detect_matches_reference_many_chunks(build, window, lam, gamma, t):
    rng = np.random.default_rng(5)
    H, W = 64, 120
    disp = np.where(rng.random((H, W)) < 0.15, rng.uniform(0.5, 60, (H, W)), 0).astype(np.float32)
    disp[10:20, 30:50] = np.where(disp[10:20, 30:50] > 0, 70.0, 0)  # a near block: occludes
    ref = ref_occlusions(disp, window, lam, gamma, t)
    for nt in (1, 2, 3):
        got = detect_occlusions(disp, window=window, lam=lam, gamma=gamma, t=t, threads=nt)
        np.testing.assert_array_equal(got, ref)


def test_points_at_both_row_ends_and_past_the_left_border(build):
    """Patches clipped at column 0 and W-1 in L, matches left of R's column 0, splats across R's last column.

    The SIMD fast paths must step aside at both row ends.
    """
    H, W = 9, 40
    rng = np.random.default_rng(2)
    left = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
    right = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
    disp = np.zeros((H, W), np.float32)
    disp[1, 0] = 0.5  # x' = -0.5: left border, L patch clipped at column 0
    disp[2, 1] = 1.25
    disp[3, W - 1] = 0.75  # L patch clipped at W-1, R splat into columns W-2, W-1
    disp[4, W - 2] = 1.5
    disp[5, 5] = 20.0  # x' = -15
    disp[6, W - 1] = 36.3
    disp[7, 20] = 3.0  # integer d: one column per patch pixel
    cfg = VPPConfig(patch=5, alpha=0.6, occlusion="off")
    for c in (3, 1):
        lc, rc = left[:, :, :c], right[:, :, :c]
        rl, rr, _ = ref_project(lc, rc, disp, cfg, seed=4)
        res = project(lc, rc, disp, cfg, seed=4)
        np.testing.assert_array_equal(res.right, rr)
        np.testing.assert_array_equal(res.left, rl)


def test_backend_falls_back_to_the_portable_build(monkeypatch):
    """No AVX2 build importable, or VPP_NO_AVX2=1: the portable build is chosen."""
    import sys

    import vpp_service.vpp as vpp_pkg

    monkeypatch.setitem(sys.modules, "vpp_service.vpp._sweep_avx2", None)  # "not built"
    monkeypatch.delattr(vpp_pkg, "_sweep_avx2", raising=False)
    assert backend.avx2_build() is None
    assert backend._choose() is backend.portable
    monkeypatch.undo()
    monkeypatch.setenv("VPP_NO_AVX2", "1")
    assert backend._choose() is backend.portable


def test_pooled_buffers_are_reset_between_calls(build):
    """Work buffers are kept between calls, yet every call gives the bytes of the reference.

    A call after a wider image, a taller occlusion window, occlusion off, or
    after release_scratch(): no state or capacity leaks from the previous call.
    """
    order = [0, 6, 5, 0, 7, 1, 6, 0]  # default, tall window, occlusion off, ...
    for k, i in enumerate(order):
        if k == 4:
            assert backend.release_scratch() >= 1
            assert backend.release_scratch() == 0  # nothing left to free
        patch, C, splat, occ, alpha, window, t, shape, density = CASES[i]
        cfg = VPPConfig(
            patch=patch,
            splat=splat,
            occlusion=occ,
            alpha=alpha,
            occ_window_x=window[0],
            occ_window_y=window[1],
            occ_t=t,
        )
        left, right, disp = case_arrays(i, shape, C, density, False)
        rl, rr, rocc = ref_project(left, right, disp, cfg, seed=i)
        res = project(left, right, disp, cfg, seed=i, threads=2)
        np.testing.assert_array_equal(res.right, rr, err_msg=f"call {k} (case {i})")
        np.testing.assert_array_equal(res.left, rl, err_msg=f"call {k} (case {i})")
        np.testing.assert_array_equal(res.occluded, rocc if occ != "off" else False)


def _ordered_disparities(kind, rng, H, W):
    """Dense maps whose paint order exercises each path of the band sort."""
    m = rng.random((H, W)) < 0.5
    if kind == "two_values":  # two crowded buckets: the stable sort of a bucket > 32
        d = np.where(rng.random((H, W)) < 0.5, 3.0, 7.25)
    elif kind == "constant":  # one d: gather order is already paint order
        d = np.full((H, W), 4.5)
    elif kind == "decreasing":  # d falls along each row: every bucket reverses
        d = np.broadcast_to(30.0 - 25.0 * np.arange(W) / W, (H, W))
    elif kind == "few_ties":  # integers 1..5: ties broken by row, then column
        d = rng.integers(1, 6, (H, W)).astype(np.float64)
    elif kind == "small_ties":  # ~2 points per value: ties inside small buckets
        d = rng.integers(8, 800, (H, W)) / 8.0
    else:  # sparse: bands of <= 24 points (insertion sort only)
        m = rng.random((H, W)) < 0.01
        d = rng.uniform(0.5, 20, (H, W))
    return np.where(m, d, 0).astype(np.float32)


@pytest.mark.parametrize("kind", ["two_values", "constant", "decreasing", "few_ties", "small_ties", "sparse"])
def test_paint_order_with_tied_and_crowded_disparities(build, kind):
    """Overlapping patches are painted far to near, ties by row then column.

    Whatever the distribution of d within a band: crowded buckets, one value, reversed.
    """
    rng = np.random.default_rng(7)
    H, W = 40, 150
    left = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
    right = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
    disp = _ordered_disparities(kind, rng, H, W)
    for occ in ("fgd", "off"):
        cfg = VPPConfig(occlusion=occ, alpha=0.7)
        rl, rr, _ = ref_project(left, right, disp, cfg, seed=3)
        for nt in (1, 2):
            res = project(left, right, disp, cfg, seed=3, threads=nt)
            np.testing.assert_array_equal(res.right, rr, err_msg=f"right, {occ}, {nt} threads")
            np.testing.assert_array_equal(res.left, rl, err_msg=f"left, {occ}, {nt} threads")
