"""Disparity accuracy metrics of the VPP evaluation protocol.

Below both the frame path (:mod:`~vpp_service.fusion`, the service's pipeline) and the evaluator
(:mod:`vpp_service.evaluation`), which both score with it.

Scored pixels are those with valid (finite, > 0) ground truth, restricted to
``mask`` when given. Over them:

* ``bad<τ>`` - percentage of scored pixels whose error ``|pred - gt|`` exceeds τ;
* ``avg`` - mean absolute error (px); ``rms`` - root mean square error (px);
* ``n`` - number of scored pixels.

**Invalid predictions.** The protocol fills a matcher's holes before scoring
(the evaluation runner does). Should a NaN prediction still reach this
function, it counts as *bad for every τ* and is *left out of* ``avg`` and
``rms`` (which are over the finite predictions only); ``invalid`` reports the
percentage of scored pixels without a prediction. With no scored pixel,
every value is NaN and ``n`` is 0.

**The three numbers every report shows** (``demo``, the live line, ``summary.json``,
``@status``, Rerun), always under these names:

* ``bad2_answered`` - bad-2 (%) over the answered pixels (those that got a value) with ground truth;
* ``density`` - the percentage of pixels with ground truth that got a value (answered);
* ``bad2_filled`` - bad-2 (%) over every pixel with ground truth after the holes are
  filled by background interpolation, as ``eval`` and ``docs/results.md`` score.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import numpy as np


def metric_key(tau: float) -> str:
    """Name of the bad-τ metric: ``bad2`` for 2, ``bad0.5`` for 0.5."""
    return f"bad{tau:g}"


def _check_inputs(
    pred: np.ndarray, gt: np.ndarray, mask: np.ndarray | None, taus: Iterable[float]
) -> tuple[float, ...]:
    """Check the arguments of :func:`compute_metrics` (raising as documented there); return ``taus`` as a tuple."""
    for name, a in (("pred", pred), ("gt", gt)):
        if not isinstance(a, np.ndarray):
            raise TypeError(f"{name}: must be a numpy array, got {type(a).__name__}")
        if a.dtype.kind not in "fiu":
            raise TypeError(f"{name}: must be numeric, got dtype {a.dtype}")
        if a.ndim != 2:
            raise ValueError(f"{name}: must be 2-D (H x W), got shape {a.shape}")
    if pred.shape != gt.shape:
        raise ValueError(f"pred: shape {pred.shape} differs from gt {gt.shape}")
    if mask is not None:
        if not isinstance(mask, np.ndarray) or mask.dtype != np.bool_:
            raise TypeError("mask: must be a bool numpy array")
        if mask.shape != gt.shape:
            raise ValueError(f"mask: shape {mask.shape} differs from gt {gt.shape}")
    checked = tuple(taus)
    if not checked:
        raise ValueError("taus: must not be empty")
    for t in checked:
        if (
            isinstance(t, bool)
            or not isinstance(t, (int, float, np.integer, np.floating))
            or not np.isfinite(t)
            or t <= 0
        ):
            raise ValueError(f"taus: every threshold must be a finite number > 0, got {t!r}")
    return checked


def compute_metrics(
    pred: np.ndarray, gt: np.ndarray, mask: np.ndarray | None = None, taus: Iterable[float] = (1, 2, 3, 4)
) -> dict[str, float]:
    """Score a disparity map against ground truth.

    Parameters
    ----------
    pred : ndarray
        H x W float disparity; NaN = no prediction (+-inf rejected).
    gt : ndarray
        H x W float ground truth; NaN, inf or <= 0 = invalid (not scored).
    mask : ndarray of bool, optional
        H x W; only True pixels are scored (e.g. a non-occlusion mask).
    taus : iterable of float
        Error thresholds in pixels (> 0), default 1, 2, 3, 4.

    Returns
    -------
    dict
        ``bad<τ>`` for each τ (percent), ``avg``, ``rms`` (px), ``invalid``
        (percent of scored pixels that are NaN in ``pred``) and ``n`` (int).

    Raises
    ------
    TypeError
        Non-array or non-numeric input, non-bool mask.
    ValueError
        Shape mismatch, non-2-D input, ``inf`` in ``pred``, bad ``taus``.
    """
    taus = _check_inputs(pred, gt, mask, taus)
    if pred.dtype.kind == "f" and np.isinf(pred).any():
        raise ValueError("pred: contains +-inf; use NaN for 'no prediction'")
    with np.errstate(invalid="ignore"):
        scored = np.isfinite(gt) & (gt > 0)
    if mask is not None:
        scored &= mask
    n = int(np.count_nonzero(scored))
    out: dict[str, float] = {}
    if n == 0:
        for t in taus:
            out[metric_key(t)] = float("nan")
        out.update(avg=float("nan"), rms=float("nan"), invalid=float("nan"), n=0)
        return out
    # whole-map passes, no gathers: |pred - gt| in float64 (exact for float32 inputs), NaN off the scored pixels
    err = np.subtract(pred, gt, dtype=np.float64)
    np.abs(err, out=err)
    np.copyto(err, np.nan, where=~scored)
    nan = np.isnan(err)
    missing = int(np.count_nonzero(nan)) - (err.size - n)  # scored pixels without a prediction
    for t in taus:
        out[metric_key(t)] = float(100.0 * (np.count_nonzero(err > t) + missing) / n)  # NaN: bad for every τ
    have = n - missing
    if have:
        np.copyto(err, 0.0, where=nan)
        out["avg"] = float(err.sum() / have)
        out["rms"] = float(np.sqrt(np.vdot(err, err) / have))
    else:
        out["avg"] = out["rms"] = float("nan")
    out["invalid"] = float(100.0 * missing / n)
    out["n"] = n
    return out


def answered_metrics(metrics: Mapping[str, float]) -> dict[str, float]:
    """``density`` and ``bad2_answered`` (percent) from one frame's raw ``bad2`` and ``invalid``.

    :func:`compute_metrics` counts a pixel without a value as bad, so
    ``bad2 = bad_answered + invalid`` (percent of the pixels with ground
    truth); this splits the two. ``{}`` when the metrics lack either key or
    nothing was scored; ``bad2_answered`` is NaN when no pixel got a value.
    """
    bad2, invalid = metrics.get("bad2"), metrics.get("invalid")
    if bad2 is None or invalid is None or not (np.isfinite(bad2) and np.isfinite(invalid)):
        return {}
    density = 100.0 - invalid
    bad = max(0.0, (bad2 - invalid) / density * 100.0) if density > 0 else float("nan")
    return {"density": density, "bad2_answered": bad}


__all__ = ["answered_metrics", "compute_metrics", "metric_key"]
