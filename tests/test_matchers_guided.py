"""Guided-stereo modulation vs the numpy formula."""

from __future__ import annotations

import numpy as np
import pytest

from vpp_service.matchers import modulate_cost


def ref_modulate(cost, hints, k, c):
    out = cost.astype(np.float64).copy()
    d = np.arange(cost.shape[2], dtype=np.float64)
    for y, x in zip(*np.nonzero(np.nan_to_num(hints, nan=0.0) > 0), strict=True):
        out[y, x] *= k * (1.0 - np.exp(-((d - float(hints[y, x])) ** 2) / (2 * c * c)))
    return out


@pytest.fixture
def volume():
    rng = np.random.default_rng(3)
    cost = rng.integers(0, 25, (6, 9, 12)).astype(np.uint16)
    hints = np.full((6, 9), np.nan, np.float32)
    pick = rng.random((6, 9)) < 0.3
    hints[pick] = rng.uniform(0.5, 11.5, pick.sum()).astype(np.float32)
    hints[0, 0] = -3.0  # <= 0: no hint
    hints[0, 1] = 0.0
    return cost, hints


@pytest.mark.parametrize(("k", "c"), [(10.0, 1.0), (3.0, 2.5), (1.0, 0.5)])
def test_float_volume_matches_formula(volume, k, c):
    cost, hints = volume
    f = cost.astype(np.float32)
    got = modulate_cost(f, hints, k, c)
    assert got.dtype == np.float32 and got is not f
    np.testing.assert_allclose(got, ref_modulate(f, hints, k, c), rtol=1e-6, atol=1e-5)
    np.testing.assert_array_equal(f, cost.astype(np.float32))  # input untouched


@pytest.mark.parametrize("dtype", [np.uint16, np.uint8])
def test_integer_volume_rounds_and_saturates(volume, dtype):
    cost, hints = volume
    cost = cost.astype(dtype)
    got = modulate_cost(cost, hints, 10.0, 1.0)
    ref = np.minimum(np.floor(ref_modulate(cost, hints, 10.0, 1.0) + 0.5), np.iinfo(dtype).max)
    assert got.dtype == dtype
    diff = np.abs(got.astype(np.int64) - ref.astype(np.int64))
    assert diff.max() <= 1 and (diff == 0).mean() > 0.99  # ties at .5 may round either way


def test_saturation_uint8():
    cost = np.full((1, 1, 40), 200, np.uint8)
    got = modulate_cost(cost, np.array([[1.0]], np.float32), 10.0, 1.0)
    assert got[0, 0, 1] == 0 and got[0, 0, 30] == 255


def test_unhinted_pixels_untouched_and_minimum_at_hint(volume):
    cost, hints = volume
    got = modulate_cost(cost, hints, 10.0, 1.0)
    none = ~(np.nan_to_num(hints) > 0)
    np.testing.assert_array_equal(got[none], cost[none])
    exact = np.full((1, 1), 4.0, np.float32)
    m = modulate_cost(np.full((1, 1, 9), 7.0, np.float32), exact)
    assert m[0, 0, 4] == 0.0 and np.argmin(m[0, 0]) == 4 and m[0, 0, 0] == pytest.approx(70.0, rel=1e-3)


def test_inplace(volume):
    cost, hints = volume
    ref = modulate_cost(cost, hints)
    out = modulate_cost(cost, hints, inplace=True, threads=1)
    assert out is cost
    np.testing.assert_array_equal(cost, ref)


@pytest.mark.parametrize(
    ("cost", "hints", "kw", "exc", "match"),
    [
        (np.zeros((2, 3, 4), np.int32), np.zeros((2, 3), np.float32), {}, TypeError, "cost"),
        (np.zeros((2, 3), np.uint16), np.zeros((2, 3), np.float32), {}, ValueError, "cost"),
        (np.zeros((2, 3, 4), np.uint16), np.zeros((2, 4), np.float32), {}, ValueError, "hints"),
        (np.zeros((2, 3, 4), np.uint16), np.zeros((2, 3), np.int32), {}, TypeError, "hints"),
        (np.zeros((2, 3, 4), np.uint16), np.full((2, 3), np.inf, np.float32), {}, ValueError, "inf"),
        (np.zeros((2, 3, 8), np.uint16)[:, :, ::2], np.zeros((2, 3), np.float32), {}, ValueError, "contiguous"),
        (np.full((2, 3, 4), np.nan, np.float32), np.zeros((2, 3), np.float32), {}, ValueError, "NaN"),
        (np.zeros((2, 3, 4), np.uint16), np.zeros((2, 3), np.float32), {"k": 0}, ValueError, "k"),
        (np.zeros((2, 3, 4), np.uint16), np.zeros((2, 3), np.float32), {"c": np.nan}, ValueError, "c"),
        (np.zeros((0, 3, 4), np.uint16), np.zeros((0, 3), np.float32), {}, ValueError, "empty"),
    ],
)
def test_bad_input(cost, hints, kw, exc, match):
    with pytest.raises(exc, match=match):
        modulate_cost(cost, hints, **kw)
