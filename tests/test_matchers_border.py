"""reject_border_matches vs a plain python reference, hand cases and bad input."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.census_sgm_reference import ref_reject
from vpp_service.matchers.border import reject_border_matches

N = np.nan


@pytest.mark.parametrize(
    ("row", "margin", "expected"),
    [
        ([0, 0, 0, 0, 0], 0, [0, 0, 0, 0, 0]),
        ([0, 0, 0, 0, 0], 1, [N, 0, 0, 0, N]),
        ([0, 0, 0, 0, 0], 2, [N, N, 0, N, N]),
        ([1, 1, 1, 1, 1], 0, [N, 1, 1, 1, 1]),  # x_r = -1 is outside the image
        ([0, 0, 1.5, 1.4, 3.4], 1, [N, 0, N, 1.4, 3.4]),  # round(1.5) = 2, as the left-right check
        ([N, 0, N, 0, N], 1, [N, 0, N, 0, N]),
    ],
)
def test_hand_cases(row, margin, expected):
    got = reject_border_matches(np.array([row], np.float32), margin)
    np.testing.assert_array_equal(got, np.array([expected], np.float32))


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("margin", [0, 1, 2, 5])
def test_matches_reference(seed, margin):
    rng = np.random.default_rng(seed)
    a = rng.uniform(-0.5, 12, (9, 30))
    a[rng.random(a.shape) < 0.3] = np.nan
    before = a.copy()
    got = reject_border_matches(a, margin)
    assert got.dtype == np.float32 and got.shape == a.shape
    np.testing.assert_array_equal(got, ref_reject(a.astype(np.float32), margin))
    np.testing.assert_array_equal(a, before)  # input untouched


def test_wide_margin_rejects_everything():
    a = np.zeros((2, 6), np.float32)
    assert np.isnan(reject_border_matches(a, 3)).all()


@pytest.mark.parametrize(
    ("disparity", "margin", "exc", "match"),
    [
        ([[1.0, 2.0]], 1, TypeError, "numpy"),
        (np.zeros((2, 2), np.int32), 1, TypeError, "float"),
        (np.zeros(4, np.float32), 1, ValueError, "2-D"),
        (np.array([[1, np.inf]], np.float32), 1, ValueError, "inf"),
        (np.zeros((2, 2), np.float32), -1, ValueError, "margin"),
        (np.zeros((2, 2), np.float32), 1.5, ValueError, "margin"),
        (np.zeros((2, 2), np.float32), True, ValueError, "margin"),
    ],
)
def test_bad_input(disparity, margin, exc, match):
    with pytest.raises(exc, match=match):
        reject_border_matches(disparity, margin)
