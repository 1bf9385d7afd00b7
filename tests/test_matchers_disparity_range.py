"""max_disparity = "auto": the range from calibration or sparse points, rounding, hysteresis, the matcher cache."""

from __future__ import annotations

import numpy as np
import pytest

from vpp_service.frame import Calibration
from vpp_service.matchers import build_matcher
from vpp_service.matchers.disparity_range import (
    AutoRangeOptions,
    DisparityRange,
    MatcherCache,
    round_range,
    wanted_range,
)

W = 400


def points(top: float, shape: tuple[int, int] = (40, W)) -> np.ndarray:
    """A sparse map: NaN except a few points, the largest ``top``."""
    s = np.full(shape, np.nan, np.float32)
    s[5, 10:20] = np.linspace(top / 4, top, 10)
    s[6, 30] = -3.0  # no point (<= 0)
    return s


def test_round_range_steps_of_16_clamped_to_limit_and_width():
    assert [round_range(v, W, 256) for v in (0.5, 16, 16.01, 75, 200)] == [16, 16, 32, 80, 208]
    assert round_range(1000, W, 256) == 256  # the limit
    assert round_range(1000, 130, 256) == 128  # below the width
    assert round_range(1000, 129, 256) == 128 and round_range(1000, 128, 256) == 112
    with pytest.raises(ValueError, match="width 16"):
        round_range(20, 16, 256)


def test_wanted_range_from_points_or_calibration():
    o = AutoRangeOptions(margin=10)
    assert wanted_range(points(60.0), None, o) == pytest.approx(70.0)
    assert wanted_range(None, None, o) is None
    assert wanted_range(np.full((4, 4), np.nan, np.float32), None, o) is None
    calib = Calibration(f=700.0, baseline=0.2, doffs=4.0)
    assert wanted_range(points(60.0), calib, o) == pytest.approx(70.0)  # min_depth_m unset: the points
    near = AutoRangeOptions(min_depth_m=1.0)
    assert wanted_range(points(60.0), calib, near) == pytest.approx(700 * 0.2 / 1.0 - 4.0)
    assert wanted_range(points(60.0), None, near) == pytest.approx(76.0)  # uncalibrated: the points


def test_near_points_get_a_larger_range_than_far_points():
    near, far = DisparityRange(), DisparityRange()
    d_near = near.update(points(150.0), None, W)
    d_far = far.update(points(20.0), None, W)
    assert d_near == 176 and d_far == 48 and d_near > d_far


def test_range_grows_at_once_and_shrinks_only_after_a_run_of_small_wants():
    r = DisparityRange(AutoRangeOptions(margin=0, shrink_after=3))
    assert r.update(points(60.0), None, W) == 64
    assert r.update(points(100.0), None, W) == 112  # grows at once
    assert r.update(points(90.0), None, W) == 112  # one step below: no churn
    assert r.update(points(40.0), None, W) == 112
    assert r.update(points(60.0), None, W) == 112
    assert r.update(points(95.0), None, W) == 112  # within a step again: the run restarts
    assert [r.update(points(v), None, W) for v in (40.0, 50.0)] == [112, 112]
    assert r.update(points(30.0), None, W) == 64  # the largest want of the run
    assert r.update(None, None, W) == 64  # no points: keeps the range in use
    assert DisparityRange(AutoRangeOptions(limit=96)).update(None, None, W) == 96  # first frame: the limit
    assert r.update(points(60.0), None, 50) == 48  # a narrower frame


def test_calibration_range_with_min_depth():
    calib = Calibration(f=721.5, baseline=0.54)
    r = DisparityRange(AutoRangeOptions(min_depth_m=3.0))
    assert r.update(points(20.0), calib, 1242) == 144  # 721.5 * 0.54 / 3 = 129.9
    assert DisparityRange(AutoRangeOptions(min_depth_m=1.0)).update(None, calib, 1242) == 256  # limit


@pytest.mark.parametrize(
    ("options", "match"),
    [
        ({"min_depth_m": -0.5}, "min_depth_m"),
        ({"min_depth_m": float("inf")}, "min_depth_m"),
        ({"margin": -1}, "margin"),
        ({"limit": 8}, "limit"),
        ({"limit": 100}, "multiple of 16"),
        ({"shrink_after": 0}, "shrink_after"),
    ],
)
def test_bad_options_rejected(options, match):
    with pytest.raises(ValueError, match=match):
        AutoRangeOptions(**options)


def test_matcher_cache_builds_once_per_range_and_stays_bounded():
    template = build_matcher("sgbm", {"max_disparity": 64, "block_size": 3})
    cache = MatcherCache(template, size=2)
    assert cache.get(64) is template
    m96 = cache.get(96)
    assert m96.options.max_disparity == 96 and m96.options.block_size == 3 and type(m96) is type(template)
    assert cache.get(96) is m96 and cache.built == 2
    cache.get(128)  # evicts the least recently used (64)
    assert cache.get(96) is m96 and cache.built == 3
    assert cache.get(64) is template and cache.built == 4  # evicted, taken again (the template has that range)
    assert len({id(cache.get(d)) for d in (64, 96)}) == 2
    with pytest.raises(ValueError, match="size"):
        MatcherCache(template, size=0)
