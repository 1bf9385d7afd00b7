"""Speckle filter vs a plain flood-fill reference."""

from collections import deque

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


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize(("max_size", "max_diff"), [(3, 1.0), (10, 2.0), (40, 0.5)])
def test_matches_reference(seed, max_size, max_diff):
    rng = np.random.default_rng(seed)
    disp = np.repeat(rng.integers(0, 6, (6, 8)), 3, axis=1).astype(np.float32) * 2.5
    disp += rng.normal(0, 0.3, disp.shape).astype(np.float32)
    disp[rng.random(disp.shape) < 0.15] = np.nan
    got = remove_speckles(disp, max_size, max_diff)
    np.testing.assert_array_equal(got, reference_speckles(disp, max_size, max_diff))


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
    ],
)
def test_bad_input(bad, exc):
    kwargs = dict(disparity=np.zeros((4, 4), np.float32), max_size=5, max_diff=1.0) | bad
    with pytest.raises(exc):
        remove_speckles(**kwargs)


def test_census_sgm_option_validated():
    with pytest.raises(ValueError, match="speckle_size"):
        build_matcher("census-sgm", {"speckle_size": -3})
