"""The whole ``census-sgm`` matcher vs the plain reference chain (tests/helpers/census_sgm_reference.py).

Exact equality on small images, on both builds of the kernels and with 1, 2 and 3 threads, including
the left band (columns x < D), guided stereo, 4 paths, the options that switch steps off, both widths
of the SGM's partial sums (uint8 when the penalties allow, else uint16) and the buffers the matcher keeps
between calls.
"""

from __future__ import annotations

import numpy as np
import pytest

from helpers.census_sgm_reference import ref_census, ref_hamming, ref_match
from helpers.frames import noisy_shifted_pair
from vpp_service.matchers import build_matcher
from vpp_service.matchers.census_sgm import p2_table
from vpp_service.matchers.guided import modulate_cost

pytestmark = pytest.mark.usefixtures("census_build")

H, W, D = 12, 40, 16


def pair(seed: int, h: int = H, w: int = W, shift: int = 5) -> tuple[np.ndarray, np.ndarray]:
    return noisy_shifted_pair(seed, h, w, shift)


def census_sgm(threads: int, **opts: object):
    return build_matcher("census-sgm", {"max_disparity": D, "threads": threads, "speckle_size": 0, **opts})


@pytest.mark.parametrize("threads", [1, 2, 3])
@pytest.mark.parametrize("seed", [0, 1])
def test_matcher_equals_reference(threads, seed):
    left, right = pair(seed)
    got = census_sgm(threads).compute(left, right)
    want = ref_match(left, right, D)
    np.testing.assert_array_equal(got, want)
    assert np.isfinite(got[:, 5:D]).mean() > 0.5  # the left band (true match inside the right image) is answered


@pytest.mark.parametrize("threads", [1, 2])
@pytest.mark.parametrize(
    "opts",
    [
        {"paths": 4},
        {"lr_check": False},
        {"median": False},
        {"lr_check": False, "median": False, "subpixel": False},
        {"uniqueness": 0.7},
        {"border_margin": 0},
        {"gap_size": 0},
        {"border_margin": 1, "gap_size": 2},
        {"border_margin": 0, "gap_size": 0, "median": False},
    ],
)
def test_matcher_options_equal_reference(threads, opts):
    left, right = pair(2)
    got = census_sgm(threads, **opts).compute(left, right)
    np.testing.assert_array_equal(got, ref_match(left, right, D, **opts))


@pytest.mark.parametrize("threads", [1, 2, 3])
@pytest.mark.parametrize(
    ("opts", "narrow"),
    [
        ({}, True),  # the defaults: max P2 = 35, 4 paths per pass: 4 * (24 + 35) <= 255, uint8 partial sums
        ({"p2_gamma": 39.0}, True),  # 4 * (24 + 39) = 252
        ({"p2_gamma": 40.0}, False),  # 4 * (24 + 40) = 256: uint16 partial sums
        ({"paths": 4, "p2_gamma": 103.0}, True),  # 2 paths per pass: 2 * (24 + 103) = 254
        ({"paths": 4, "p2_gamma": 104.0}, False),
        ({"p1": 60, "p2_min": 200}, False),  # path costs up to 224: uint8 sums of 4 would wrap
    ],
)
def test_partial_sum_width_equals_reference(census_build, threads, opts, narrow):
    o = {"paths": 8, "p1": 11, "p2_min": 17, "p2_alpha": 0.5, "p2_gamma": 35.0, **opts}
    lut = p2_table(o["p1"], o["p2_min"], o["p2_alpha"], o["p2_gamma"])
    assert census_build.narrow_sums(o["paths"], lut, False) is narrow
    assert census_build.narrow_sums(o["paths"], lut, True) is False  # a cost volume (guided stereo): uint16
    left, right = pair(10)
    got = census_sgm(threads, **opts).compute(left, right)
    np.testing.assert_array_equal(got, ref_match(left, right, D, **opts))


@pytest.mark.parametrize("threads", [1, 2])
@pytest.mark.parametrize("d", [32, 48, 64])
def test_byte_path_costs_equal_reference(census_build, threads, d):
    """D = 32, 48, 64: whole 32-disparity blocks and a half block, a left band wider than a block."""
    lut = p2_table()
    assert census_build.byte_path_costs(8, lut, False, d) is census_build.AVX2  # the uint8 path costs run
    assert census_build.byte_path_costs(4, lut, False, d) is False
    assert census_build.byte_path_costs(8, lut, True, d) is False  # guided stereo: a cost volume
    assert census_build.byte_path_costs(8, p2_table(gamma=40.0), False, d) is False  # uint16 sums
    left, right = pair(11, 10, 90, 7)
    m = build_matcher("census-sgm", {"max_disparity": d, "threads": threads, "speckle_size": 0})
    np.testing.assert_array_equal(m.compute(left, right), ref_match(left, right, d))


@pytest.mark.parametrize("threads", [1, 2])
@pytest.mark.parametrize("d", [20, 128, 144])
def test_keyed_wta_equals_reference(census_build, threads, d):
    """D = 20 (part of a 16-disparity block), 128 (the largest with keys), 144 (no keys: plain WTA).

    Flat stripes in the right image give tied costs (the lowest d wins) and rejected pixels.
    """
    lut = p2_table()
    assert census_build.keyed_wta(8, lut, False, d) is (census_build.AVX2 and d <= 128)
    assert census_build.keyed_wta(4, lut, False, d) is (census_build.AVX2 and d <= 128)  # also narrow
    assert census_build.keyed_wta(8, lut, True, d) is False  # guided stereo: a cost volume, uint16 sums
    assert census_build.keyed_wta(8, p2_table(gamma=40.0), False, d) is False  # uint16 sums: sums > 510
    left, right = pair(12, 8, d + 40, 9)
    right[:, 30:36] = 128
    right[:, d : d + 3] = 40
    m = build_matcher("census-sgm", {"max_disparity": d, "threads": threads, "speckle_size": 0})
    np.testing.assert_array_equal(m.compute(left, right), ref_match(left, right, d))


@pytest.mark.parametrize("threads", [1, 2])
def test_guided_equals_reference(threads):
    left, right = pair(3)
    rng = np.random.default_rng(3)
    hints = np.where(rng.random((H, W)) < 0.2, rng.uniform(1, D - 1, (H, W)), np.nan).astype(np.float32)
    cost = modulate_cost(ref_hamming(ref_census(left), ref_census(right), D), hints, 10.0, 1.0)
    got = census_sgm(threads).compute(left, right, hints=hints)
    np.testing.assert_array_equal(got, ref_match(left, right, D, cost=cost))


@pytest.mark.parametrize("threads", [1, 2])
def test_compute_from_cost_equals_reference(threads):
    left, right = pair(4)
    rng = np.random.default_rng(4)
    cost = rng.integers(0, 6000, (H, W, D)).astype(np.uint16)  # above COST_CAP too
    m = census_sgm(threads)
    got = m.compute_from_cost(cost, left)
    np.testing.assert_array_equal(got, ref_match(left, right, D, cost=cost))
    assert cost.max() >= 5000  # not modified


def test_kept_buffers_follow_shape_disparities_and_threads():
    m = census_sgm(2)
    for h, w, seed in [(12, 40, 5), (9, 33, 6), (12, 40, 7)]:
        left, right = pair(seed, h, w)
        np.testing.assert_array_equal(m.compute(left, right), ref_match(left, right, D))
    m2 = build_matcher("census-sgm", {"max_disparity": 8, "threads": 1, "speckle_size": 0})
    left, right = pair(8)
    np.testing.assert_array_equal(m2.compute(left, right), ref_match(left, right, 8))
    a = m.compute(left, right)
    b = m.compute(left, right)
    assert a is not b  # each call returns its own array
    np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("threads", [1, 2])
def test_wide_disparity_range_and_odd_sizes(threads):
    # D not a multiple of the SIMD width, the band covers most of the image
    left, right = pair(9, 7, 29, 3)
    m = build_matcher("census-sgm", {"max_disparity": 23, "threads": threads, "speckle_size": 0})
    np.testing.assert_array_equal(m.compute(left, right), ref_match(left, right, 23))
