"""The confidence curve (vpp_service.evaluation.confidence): counts by hand, the issue's target on shared data."""

from __future__ import annotations

import math

import numpy as np
import pytest

from helpers.shared_data import need_shared
from vpp_service.evaluation.confidence import THRESHOLDS, confidence_curve, frame_counts, summarize


def test_frame_counts_by_hand():
    gt = np.array([[10.0, 10.0, 10.0, 10.0, np.nan, 0.0]], np.float32)
    disp = np.array([[10.5, 14.0, 11.0, np.nan, 3.0, 4.0]], np.float32)
    conf = np.array([[0.9, 0.2, 0.5, 0.0, 1.0, 1.0]], np.float32)
    # answered with valid GT: x = 0, 1, 2 (x = 4, 5: no GT); bad: x = 1 (4 px off)
    got = frame_counts(disp, conf, gt, (0.1, 0.5, 0.95))
    assert got == {"answered": 3, "bad": 1, "kept": [3, 2, 0], "kept_bad": [1, 0, 0]}
    with pytest.raises(ValueError, match="shapes"):
        frame_counts(disp, conf[:, :3], gt)


def test_summarize_means_and_pools():
    rows = [
        {"answered": 100, "bad": 10, "kept": [80], "kept_bad": [2]},
        {"answered": 300, "bad": 6, "kept": [150], "kept_bad": [3]},
    ]
    s = summarize(rows, (0.5,))
    assert s["frames"] == 2
    assert s["bad2_answered"] == pytest.approx((10.0 + 2.0) / 2)
    assert s["bad2_answered_pooled"] == pytest.approx(100 * 16 / 400)
    (p,) = s["points"]
    assert p["kept"] == pytest.approx((80.0 + 50.0) / 2) and p["bad2_kept"] == pytest.approx((2.5 + 2.0) / 2)
    assert p["kept_pooled"] == pytest.approx(100 * 230 / 400) and p["bad2_kept_pooled"] == pytest.approx(100 * 5 / 230)
    nothing = summarize([{"answered": 0, "bad": 0, "kept": [0], "kept_bad": [0]}, *rows], (0.5,))
    assert math.isfinite(nothing["bad2_answered"])  # a frame without an answer is left out of the means


def test_keeping_confident_pixels_cuts_bad2_by_a_third_on_the_shared_scenes():
    """Issue 36's target: confidence >= 0.5 keeps >= 70 % of the answered pixels, bad-2 on them a third lower.

    census-sgm + VPP (5 % points) on every shared Middlebury 2005/2006 scene, pooled and on average.
    """
    from vpp_service.datasets import open_dataset

    ds = open_dataset("auto", need_shared("middlebury2005_2006_thirdsize"))
    rows = confidence_curve(ds, "census-sgm", density=0.05, seed=0)
    assert len(rows) == len(ds) >= 20
    s = summarize(rows, THRESHOLDS)
    at = next(p for p in s["points"] if p["threshold"] == 0.5)
    assert at["kept"] >= 70 and at["kept_pooled"] >= 70
    assert at["bad2_kept"] <= 2 / 3 * s["bad2_answered"]
    assert at["bad2_kept_pooled"] <= 2 / 3 * s["bad2_answered_pooled"]
    kept = [p["kept"] for p in s["points"]]
    assert kept == sorted(kept, reverse=True)  # a higher threshold never keeps more
