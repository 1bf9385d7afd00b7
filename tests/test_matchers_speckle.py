"""Speckle filter vs a plain flood-fill reference and OpenCV's ``filterSpeckles``."""

from collections import deque

import cv2
import numpy as np
import pytest

from vpp_service.matchers import build_matcher, remove_speckles


def reference_speckles(disp: np.ndarray, max_size: int, max_diff: float) -> np.ndarray:
    """Literal 4-connected flood fill on the 1/16-px quantised map."""
    q = np.where(np.isfinite(disp), np.rint(disp * 16), np.nan)
    h, w = disp.shape
    out = disp.copy()
    seen = np.zeros((h, w), bool)
    for y0 in range(h):
        for x0 in range(w):
            if seen[y0, x0] or np.isnan(q[y0, x0]):
                continue
            region, todo = [], deque([(y0, x0)])
            seen[y0, x0] = True
            while todo:
                y, x = todo.popleft()
                region.append((y, x))
                for yy, xx in ((y - 1, x), (y + 1, x), (y, x - 1), (y, x + 1)):
                    if (
                        0 <= yy < h
                        and 0 <= xx < w
                        and not seen[yy, xx]
                        and not np.isnan(q[yy, xx])
                        and abs(q[yy, xx] - q[y, x]) <= round(max_diff * 16)
                    ):
                        seen[yy, xx] = True
                        todo.append((yy, xx))
            if len(region) <= max_size:
                for y, x in region:
                    out[y, x] = np.nan
    return out


def opencv_speckles(disp: np.ndarray, max_size: int, max_diff: float) -> np.ndarray:
    """OpenCV's flood fill on the 1/16-px int16 map (the filter this one reproduces)."""
    valid = np.isfinite(disp)
    fixed = np.full(disp.shape, -16, np.int16)
    fixed[valid] = np.rint(disp[valid] * 16).astype(np.int16)
    cv2.filterSpeckles(fixed, -16, max_size, round(max_diff * 16))
    return np.where((fixed == -16) & valid, np.float32(np.nan), disp)


def blocky(seed: int, h: int, w: int, nan_share: float = 0.15) -> np.ndarray:
    """Piecewise-constant disparity (blocks of 3 columns) with noise and NaN holes."""
    rng = np.random.default_rng(seed)
    disp = np.repeat(rng.integers(0, 6, (h, -(-w // 3))), 3, axis=1)[:, :w].astype(np.float32) * 2.5
    disp += rng.normal(0, 0.3, disp.shape).astype(np.float32)
    disp[rng.random(disp.shape) < nan_share] = np.nan
    return disp


@pytest.mark.parametrize("threads", [1, 2, 3])
@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize(("max_size", "max_diff"), [(3, 1.0), (10, 2.0), (40, 0.5)])
def test_matches_reference(seed, max_size, max_diff, threads):
    disp = blocky(seed, 6, 24)
    got = remove_speckles(disp, max_size, max_diff, threads=threads)
    np.testing.assert_array_equal(got, reference_speckles(disp, max_size, max_diff))


@pytest.mark.parametrize("threads", [1, 2, 5])
@pytest.mark.parametrize(("shape", "max_size"), [((120, 150), 200), ((61, 333), 25), ((1, 400), 4), ((300, 1), 4)])
def test_matches_opencv_on_larger_maps(shape, max_size, threads):
    """Regions crossing the threads' row strips are joined exactly as OpenCV's flood fill joins them."""
    disp = blocky(7, *shape, nan_share=0.1)
    got = remove_speckles(disp, max_size, 2.0, threads=threads)
    np.testing.assert_array_equal(got, opencv_speckles(disp, max_size, 2.0))
    assert np.isnan(got).sum() > np.isnan(disp).sum()  # something was removed


def test_non_finite_input_kept_and_nothing_joins_through_it():
    disp = np.full((5, 9), 4.0, np.float32)
    disp[:, 4] = [np.inf, -np.inf, np.nan, np.inf, np.nan]  # a wall: left and right are two regions of 20
    disp[0, 0] = 9.0
    got = remove_speckles(disp, 20, 2.0, threads=2)
    assert np.isnan(got[:, :4]).all() and np.isnan(got[:, 5:]).all()
    np.testing.assert_array_equal(got[:, 4], disp[:, 4])  # inf stays inf, NaN stays NaN
    assert np.isfinite(remove_speckles(disp, 19, 2.0)[:, 5:]).all()


def test_all_invalid_and_non_contiguous_input():
    nan = np.full((4, 6), np.nan, np.float32)
    assert np.isnan(remove_speckles(nan, 5, 1.0)).all()
    disp = blocky(3, 20, 30)
    view = disp[:, ::2]
    np.testing.assert_array_equal(
        remove_speckles(view, 10, 2.0), reference_speckles(np.ascontiguousarray(view), 10, 2.0)
    )
    disp_before = disp.copy()
    remove_speckles(disp, 10, 2.0)
    np.testing.assert_array_equal(disp, disp_before)  # not modified


@pytest.mark.parametrize("value", [2048.0, -2047.9375, 1e30])
def test_out_of_range_disparity_rejected(value):
    disp = np.zeros((3, 3), np.float32)
    disp[1, 1] = value
    with pytest.raises(ValueError, match="2047"):
        remove_speckles(disp, 5, 1.0, threads=2)
    disp[1, 1] = 2047.9
    assert remove_speckles(disp, 5, 1.0).shape == (3, 3)


def test_small_island_removed_large_kept():
    disp = np.full((20, 20), 10.0, np.float32)
    disp[5:7, 5:7] = 30.0  # 4-pixel island
    out = remove_speckles(disp, max_size=10, max_diff=2.0)
    assert np.isnan(out[5:7, 5:7]).all()
    assert np.isfinite(out).sum() == 400 - 4
    assert remove_speckles(disp, max_size=0).tolist() == disp.tolist()


@pytest.mark.parametrize(
    ("bad", "exc"),
    [
        (dict(disparity=np.zeros((4, 4), np.float64)), TypeError),
        (dict(disparity=np.zeros((4, 4, 1), np.float32)), ValueError),
        (dict(disparity=np.zeros((0, 4), np.float32)), ValueError),
        (dict(max_size=-1), ValueError),
        (dict(max_diff=float("nan")), ValueError),
        (dict(max_diff=-0.5), ValueError),
        (dict(threads=0), ValueError),
    ],
)
def test_bad_input(bad, exc):
    kwargs = dict(disparity=np.zeros((4, 4), np.float32), max_size=5, max_diff=1.0) | bad
    with pytest.raises(exc):
        remove_speckles(**kwargs)


def test_census_sgm_option_validated():
    with pytest.raises(ValueError, match="speckle_size"):
        build_matcher("census-sgm", {"speckle_size": -3})
