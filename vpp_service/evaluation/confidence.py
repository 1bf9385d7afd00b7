"""How well the per-pixel confidence ranks a matcher's answers: bad-2 of the kept pixels against the fraction kept.

For each frame with ground truth, :func:`confidence_curve` draws the sparse
points (the ``uniform`` sensor at ``density``, seeded), runs the fusion step with
VPP (or the matcher alone) asking for the confidence
(:func:`vpp_service.fusion.fuse`, ``confidence=True``), and counts, over the
pixels with valid ground truth (finite, > 0) that the matcher answered (not
NaN; holes are not filled), how many are wrong by more than 2 px (bad-2) and,
for every threshold ``t``, how many have ``confidence >= t`` and how many of
those are wrong. :func:`summarize` turns the counts into the curve: for each
threshold, the fraction of the answered pixels kept and bad-2 on the kept
pixels, as the mean over frames and pooled over every pixel.

This is what ``min_confidence`` trades: a threshold ``t`` keeps exactly the
pixels counted as kept at ``t``.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np

from vpp_service.frame import StereoFrame

if TYPE_CHECKING:
    from vpp_service.matchers.base import Matcher
    from vpp_service.vpp import VPPConfig

#: The thresholds of the curve.
THRESHOLDS = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9)
#: Error (px) above which an answered pixel is wrong.
BAD_PX = 2.0


def frame_counts(
    disparity: np.ndarray, confidence: np.ndarray, gt: np.ndarray, thresholds: Sequence[float] = THRESHOLDS
) -> dict[str, object]:
    """The counts of one frame: ``answered``, ``bad`` and per threshold ``kept``, ``kept_bad`` (lists).

    Parameters
    ----------
    disparity, confidence, gt : ndarray
        H x W float maps: the matcher's disparity (NaN = no answer), its confidence, the ground truth
        (finite and > 0 = valid).
    thresholds : sequence of float
        The confidence thresholds.
    """
    if not disparity.shape == confidence.shape == gt.shape:
        raise ValueError(
            f"disparity, confidence, gt: shapes differ ({disparity.shape}, {confidence.shape}, {gt.shape})"
        )
    with np.errstate(invalid="ignore"):
        answered = np.isfinite(disparity) & np.isfinite(gt) & (gt > 0)
        bad = answered & ~(np.abs(disparity - gt) <= BAD_PX)
    kept = [answered & (confidence >= np.float32(t)) for t in thresholds]
    return {
        "answered": int(answered.sum()),
        "bad": int(bad.sum()),
        "kept": [int(k.sum()) for k in kept],
        "kept_bad": [int((k & bad).sum()) for k in kept],
    }


def confidence_curve(
    frames: Iterable[StereoFrame],
    matcher: str = "census-sgm",
    *,
    matcher_options: Mapping[str, object] | None = None,
    vpp: bool = True,
    vpp_config: VPPConfig | None = None,
    density: float = 0.05,
    seed: int = 0,
    thresholds: Sequence[float] = THRESHOLDS,
) -> list[dict[str, object]]:
    """Per-frame counts (:func:`frame_counts`) of ``matcher`` with VPP (or alone) on frames with ground truth.

    Parameters
    ----------
    frames : iterable of StereoFrame
        Frames with ``gt_disparity`` (a dataset reader works).
    matcher : str
        Registered matcher name, built per frame with the frame's default range
        (:func:`~vpp_service.evaluation.runner.default_max_disparity`) over ``matcher_options``.
    vpp : bool
        Paint the pair with VPP on the drawn points (else the matcher alone on the raw pair).
    vpp_config : VPPConfig or None
        VPP settings (None: the matcher's preferred ones over VPP's defaults).
    density, seed
        The ``uniform`` sensor's density (fraction of valid ground-truth pixels) and the seed of the draw
        and of VPP's pattern.
    thresholds : sequence of float
        The confidence thresholds.

    Returns
    -------
    list of dict
        One row per frame: ``scene``, ``dataset``, ``max_disparity`` and the counts.
    """
    from vpp_service.evaluation.runner import default_max_disparity
    from vpp_service.fusion import fuse
    from vpp_service.matchers import build_matcher
    from vpp_service.settings import from_mapping
    from vpp_service.sources.sensors import build_sensor
    from vpp_service.vpp import VPPConfig

    sensor = build_sensor("uniform", {"density": density})
    rows: list[dict[str, object]] = []
    for frame in frames:
        gt = frame.gt_disparity
        if gt is None:
            raise ValueError(f"frames: frame {frame.name!r} has no gt_disparity")
        md = default_max_disparity(gt, gt.shape[1])
        m: Matcher = build_matcher(matcher, {**(matcher_options or {}), "max_disparity": md, "fill": False})
        cfg = None
        if vpp:
            cfg = vpp_config or from_mapping(VPPConfig, m.preferred_vpp(m.options), f"matcher.{m.name}: vpp")
        drawn = sensor.simulate(frame, seed=seed)
        with_points = frame.with_(sparse_disparity=drawn.sparse_disparity, sensor_depth=None)
        res = fuse(with_points, m, cfg, seed=seed, depth=False, confidence=True, depth_filter=None)
        assert res.confidence is not None  # asked for
        counts = frame_counts(res.disparity, res.confidence, gt, thresholds)
        rows.append({"scene": frame.name, "dataset": frame.meta.get("dataset", ""), "max_disparity": md, **counts})
    return rows


def _ratio(num: float, den: float) -> float:
    return num / den if den else float("nan")


def summarize(rows: Sequence[Mapping[str, object]], thresholds: Sequence[float] = THRESHOLDS) -> dict[str, object]:
    """The curve from per-frame counts: bad-2 of all answered pixels, and per threshold kept and bad-2 kept.

    Returns
    -------
    dict
        ``bad2_answered`` (percent), ``points``: one dict per threshold with ``threshold``, ``kept``
        (percent of the answered pixels), ``bad2_kept`` (percent of the kept ones), each the mean over
        frames, and ``kept_pooled``, ``bad2_kept_pooled`` over every pixel of every frame; the
        ``bad2_answered_pooled`` likewise.
    """
    if not rows:
        raise ValueError("rows: no frames to summarize")

    def ints(r: Mapping[str, object], key: str) -> list[int]:
        v = r[key]
        assert isinstance(v, list)
        return [int(x) for x in v]

    def num(r: Mapping[str, object], key: str) -> int:
        v = r[key]
        assert isinstance(v, int)
        return v

    ans = np.array([num(r, "answered") for r in rows], float)
    bad = np.array([num(r, "bad") for r in rows], float)
    kept = np.array([ints(r, "kept") for r in rows], float)
    kept_bad = np.array([ints(r, "kept_bad") for r in rows], float)
    with np.errstate(invalid="ignore", divide="ignore"):
        points = [
            {
                "threshold": float(t),
                "kept": float(np.nanmean(100 * kept[:, i] / ans)),
                "bad2_kept": float(np.nanmean(100 * kept_bad[:, i] / kept[:, i])),
                "kept_pooled": 100 * _ratio(kept[:, i].sum(), ans.sum()),
                "bad2_kept_pooled": 100 * _ratio(kept_bad[:, i].sum(), kept[:, i].sum()),
            }
            for i, t in enumerate(thresholds)
        ]
        return {
            "frames": len(rows),
            "bad2_answered": float(np.nanmean(100 * bad / ans)),
            "bad2_answered_pooled": 100 * _ratio(bad.sum(), ans.sum()),
            "points": points,
        }


__all__ = ["BAD_PX", "THRESHOLDS", "confidence_curve", "frame_counts", "summarize"]
