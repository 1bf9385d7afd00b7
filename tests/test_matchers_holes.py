"""fill_holes (background interpolation) and fill_short_gaps vs python references and hand cases."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.census_sgm_reference import ref_short_gaps
from vpp_service.matchers import fill_holes
from vpp_service.matchers.holes import fill_short_gaps

N = np.nan


def ref_fill(a, empty=np.nan):
    out = a.astype(np.float32).copy()
    for y in range(a.shape[0]):
        row = a[y]
        valid = np.nonzero(~np.isnan(row))[0]
        for x in np.nonzero(np.isnan(row))[0]:
            left = valid[valid < x]
            right = valid[valid > x]
            cands = ([row[left[-1]]] if left.size else []) + ([row[right[0]]] if right.size else [])
            out[y, x] = min(cands) if cands else empty
    return out


@pytest.mark.parametrize(
    ("row", "expected"),
    [
        ([1, N, 3], [1, 1, 3]),
        ([5, N, N, 2], [5, 2, 2, 2]),
        ([N, N, 4, 6], [4, 4, 4, 6]),
        ([4, 6, N], [4, 6, 6]),
        ([N], [N]),
        ([N, N, N], [N, N, N]),
        ([7, 8, 9], [7, 8, 9]),
        ([N, 3, N, N, 5, 1, N], [3, 3, 3, 3, 5, 1, 1]),
    ],
)
def test_hand_cases(row, expected):
    got = fill_holes(np.array([row], np.float32))
    np.testing.assert_array_equal(got, np.array([expected], np.float32))


def test_empty_row_value():
    a = np.array([[N, N], [1, N]], np.float32)
    np.testing.assert_array_equal(fill_holes(a, empty=0.0), [[0, 0], [1, 1]])


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_matches_reference(seed, dtype):
    rng = np.random.default_rng(seed)
    a = rng.uniform(0, 50, (12, 17)).astype(dtype)
    a[rng.random(a.shape) < 0.4] = np.nan
    a[3] = np.nan
    before = a.copy()
    got = fill_holes(a, threads=2)
    assert got.dtype == np.float32
    np.testing.assert_array_equal(got, ref_fill(a.astype(np.float32)))
    np.testing.assert_array_equal(a, before)  # input untouched
    assert not np.isnan(np.delete(got, 3, axis=0)).any()


def test_non_contiguous_input_accepted():
    a = np.array([[1, N, 3, N, 9, N]], np.float32)[:, ::2]
    np.testing.assert_array_equal(fill_holes(a), [[1, 3, 9]])


@pytest.mark.parametrize(
    ("arg", "exc", "match"),
    [
        ([[1.0, N]], TypeError, "numpy"),
        (np.zeros((2, 2), np.int32), TypeError, "float"),
        (np.zeros(4, np.float32), ValueError, "2-D"),
        (np.zeros((0, 3), np.float32), ValueError, "empty"),
        (np.array([[1, np.inf]], np.float32), ValueError, "inf"),
    ],
)
def test_bad_input(arg, exc, match):
    with pytest.raises(exc, match=match):
        fill_holes(arg)


@pytest.mark.parametrize(
    ("row", "max_gap", "expected"),
    [
        ([1, N, 3], 4, [1, 2, 3]),  # one surface: linear
        ([1, N, N, N, 3], 4, [1, 1.5, 2, 2.5, 3]),
        ([1, N, 9], 4, [1, 1, 9]),  # step > max_step: background (smaller end)
        ([9, N, N, 1], 4, [9, 1, 1, 1]),
        ([1, N, N, 3], 1, [1, N, N, 3]),  # longer than max_gap: untouched
        ([N, 2, N, 4, N], 4, [N, 2, 3, 4, N]),  # runs at the borders stay holes
        ([N, N, N], 4, [N, N, N]),
        ([1, N, 3], 0, [1, N, 3]),  # 0 = off
        ([7, 8, 9], 4, [7, 8, 9]),
    ],
)
def test_short_gaps_hand_cases(row, max_gap, expected):
    got = fill_short_gaps(np.array([row], np.float32), max_gap=max_gap)
    np.testing.assert_array_equal(got, np.array([expected], np.float32))


def test_short_gaps_max_step():
    a = np.array([[1, N, 4]], np.float32)
    np.testing.assert_array_equal(fill_short_gaps(a, max_step=3.0), [[1, 2.5, 4]])
    np.testing.assert_array_equal(fill_short_gaps(a, max_step=2.9), [[1, 1, 4]])


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize(("max_gap", "max_step"), [(1, 2.0), (4, 2.0), (6, 0.5), (50, 100.0)])
def test_short_gaps_match_reference(seed, max_gap, max_step):
    rng = np.random.default_rng(seed)
    a = rng.uniform(0, 8, (12, 40)).astype(np.float64)
    a[rng.random(a.shape) < 0.45] = np.nan
    a[3] = np.nan
    before = a.copy()
    got = fill_short_gaps(a, max_gap=max_gap, max_step=max_step, threads=2)
    assert got.dtype == np.float32
    np.testing.assert_array_equal(got, ref_short_gaps(a.astype(np.float32), max_gap, max_step))
    np.testing.assert_array_equal(a, before)  # input untouched
    np.testing.assert_array_equal(got, fill_short_gaps(a, max_gap=max_gap, max_step=max_step, threads=1))


@pytest.mark.parametrize(
    ("kwargs", "exc", "match"),
    [
        ({"disparity": [[1.0, N]]}, TypeError, "numpy"),
        ({"disparity": np.zeros((2, 2), np.int32)}, TypeError, "float"),
        ({"disparity": np.zeros(4, np.float32)}, ValueError, "2-D"),
        ({"disparity": np.array([[1, np.inf]], np.float32)}, ValueError, "inf"),
        ({"max_gap": -1}, ValueError, "max_gap"),
        ({"max_gap": 2.5}, ValueError, "max_gap"),
        ({"max_gap": True}, ValueError, "max_gap"),
        ({"max_step": -0.5}, ValueError, "max_step"),
        ({"max_step": float("nan")}, ValueError, "max_step"),
        ({"max_step": "2"}, ValueError, "max_step"),
    ],
)
def test_short_gaps_bad_input(kwargs, exc, match):
    args = {"disparity": np.array([[1, N, 3]], np.float32), **kwargs}
    with pytest.raises(exc, match=match):
        fill_short_gaps(**args)
