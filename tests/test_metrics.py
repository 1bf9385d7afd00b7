"""compute_metrics against hand-computed values and a plain reference."""

from __future__ import annotations

import numpy as np
import pytest

from vpp_service.metrics import compute_metrics, metric_key


@pytest.fixture
def pair():
    gt = np.array([[1.0, 2.0, np.nan], [4.0, 5.0, 6.0]], np.float32)
    pred = np.array([[1.5, 4.5, 9.0], [4.0, np.nan, 2.0]], np.float32)
    return pred, gt


def test_hand_computed(pair):
    pred, gt = pair
    m = compute_metrics(pred, gt)
    # scored: 5 pixels (gt NaN excluded); errors 0.5, 2.5, 0, NaN, 4
    assert m["n"] == 5
    assert m["bad1"] == pytest.approx(100 * 3 / 5)  # 2.5, NaN, 4
    assert m["bad2"] == pytest.approx(100 * 3 / 5)
    assert m["bad3"] == pytest.approx(100 * 2 / 5)  # NaN, 4
    assert m["bad4"] == pytest.approx(100 * 1 / 5)  # NaN only (4 is not > 4)
    assert m["avg"] == pytest.approx((0.5 + 2.5 + 0 + 4) / 4)
    assert m["rms"] == pytest.approx(np.sqrt((0.25 + 6.25 + 0 + 16) / 4))
    assert m["invalid"] == pytest.approx(20.0)


def test_mask_and_custom_taus(pair):
    pred, gt = pair
    mask = np.array([[True, True, True], [False, False, False]])
    m = compute_metrics(pred, gt, mask=mask, taus=(0.5, 2))
    assert set(m) == {"bad0.5", "bad2", "avg", "rms", "invalid", "n"}
    assert m["n"] == 2 and m["bad0.5"] == 50.0 and m["bad2"] == 50.0 and m["avg"] == pytest.approx(1.5)
    assert metric_key(0.5) == "bad0.5" and metric_key(3) == "bad3"


def test_matches_reference_on_random_maps():
    rng = np.random.default_rng(0)
    gt = rng.uniform(0, 50, (40, 60)).astype(np.float32)
    gt[rng.random(gt.shape) < 0.2] = np.nan
    gt[0, 0] = -1.0  # <= 0 is invalid too
    pred = gt + rng.normal(0, 2, gt.shape).astype(np.float32)
    pred[rng.random(gt.shape) < 0.05] = np.nan
    m = compute_metrics(pred, gt)
    bad = dict.fromkeys((1, 2, 3, 4), 0)
    errs, n = [], 0
    for p, g in zip(pred.ravel(), gt.ravel(), strict=True):
        if not np.isfinite(g) or g <= 0:
            continue
        n += 1
        if np.isnan(p):
            for t in bad:
                bad[t] += 1
            continue
        e = abs(float(p) - float(g))
        errs.append(e)
        for t in bad:
            bad[t] += e > t
    assert m["n"] == n
    for t in bad:
        assert m[f"bad{t}"] == pytest.approx(100 * bad[t] / n)
    assert m["avg"] == pytest.approx(np.mean(errs), rel=1e-6)
    assert m["rms"] == pytest.approx(np.sqrt(np.mean(np.square(errs))), rel=1e-6)


def test_perfect_and_empty():
    gt = np.full((3, 3), 7.0, np.float32)
    m = compute_metrics(gt.copy(), gt)
    assert m["bad1"] == 0 and m["avg"] == 0 and m["rms"] == 0 and m["n"] == 9
    e = compute_metrics(gt, np.full((3, 3), np.nan, np.float32))
    assert e["n"] == 0 and np.isnan(e["bad2"]) and np.isnan(e["avg"])
    allnan = compute_metrics(np.full((3, 3), np.nan, np.float32), gt)
    assert allnan["bad1"] == 100.0 and np.isnan(allnan["avg"]) and allnan["invalid"] == 100.0


@pytest.mark.parametrize(
    ("pred", "gt", "kw", "exc", "match"),
    [
        ([[1.0]], np.ones((1, 1)), {}, TypeError, "pred"),
        (np.ones((2, 2)), np.ones((2, 3)), {}, ValueError, "pred"),
        (np.ones(4), np.ones(4), {}, ValueError, "pred"),
        (np.array([[np.inf]]), np.ones((1, 1)), {}, ValueError, "inf"),
        (np.ones((2, 2)), np.ones((2, 2)), {"mask": np.ones((2, 2))}, TypeError, "mask"),
        (np.ones((2, 2)), np.ones((2, 2)), {"mask": np.ones((1, 2), bool)}, ValueError, "mask"),
        (np.ones((2, 2)), np.ones((2, 2)), {"taus": ()}, ValueError, "taus"),
        (np.ones((2, 2)), np.ones((2, 2)), {"taus": (0,)}, ValueError, "taus"),
        (np.ones((2, 2)), np.array([["a", "b"], ["c", "d"]]), {}, TypeError, "gt"),
    ],
)
def test_errors(pred, gt, kw, exc, match):
    with pytest.raises(exc, match=match):
        compute_metrics(pred, gt, **kw)
