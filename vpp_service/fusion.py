"""The per-frame fusion step: sparse depth -> VPP -> matcher -> depth, metrics.

:func:`fuse` is the one implementation of the step; the service's
:class:`Fusion` (the pipeline's process stage), the ``eval`` runner, the
``demo`` command and the benchmarks all call it.

* **Sparse points.** The frame's ``sparse_disparity``, or its metric
  ``sensor_depth`` converted with its calibration (``d = f * b / Z - doffs``)
  (:func:`sparse_disparity`).
* **See-through filter.** Before VPP or guidance, the sparse points pass the
  ``depth_filter`` (:class:`~vpp_service.vpp.see_through.DepthFilter`; by
  default ``auto``: the frames that declare LiDAR-like points with
  ``meta["lidar_like"]``): a point with a clearly nearer point in its image
  neighbourhood is dropped (a LiDAR beside the camera saw it past a
  foreground edge). ``FusionResult.see_through`` counts the dropped points
  (None when the filter did not run) and ``timing_ms["depth_filter"]`` its time.
* **VPP.** With a :class:`~vpp_service.vpp.VPPConfig` and sparse points, the
  pair is painted (:func:`vpp_service.vpp.project`, pattern seed ``seed``) and
  the matcher runs on the painted pair. When none of the points is usable
  (none with ``0 < d < width``, as counted by VPP itself) the matcher runs on
  the raw pair and ``left_vpp`` / ``right_vpp`` / ``occluded`` stay None;
  ``vpp_stats`` holds the counts either way (:meth:`VPPStats.to_dict
  <vpp_service.vpp.VPPStats.to_dict>`).
* **Guided stereo** (``guide=True``). The sparse points are passed to the
  matcher as ``hints`` (only matchers with ``supports_guidance``).
* **Depth clip.** With a ``depth_clip``
  (:class:`~vpp_service.matchers.depth_clip.DepthClip`, the service's
  ``[depth_clip]``), disparities outside the valid depth range (by default
  from the matcher's range and the rig: nothing below ``max(min_disparity, 1)``
  px, nothing above the top of the range) become NaN, before depth, metrics and
  every output, so they all agree on what is invalid.
* **Confidence.** With ``confidence=True`` the matcher runs
  :meth:`~vpp_service.matchers.Matcher.compute_with_confidence` and
  ``FusionResult.confidence`` carries its map (0 wherever the disparity is
  NaN, the depth clip's holes included). The matcher's ``min_confidence``
  applies either way (its low-confidence pixels are holes).
* **Depth.** With ``depth=True`` and a calibration, metric depth of the result.
* **Metrics.** When the frame carries ground truth,
  :func:`~vpp_service.metrics.compute_metrics` of the disparity over
  all valid-GT pixels. ``protocol=True`` scores as the evaluation protocol
  does: the matcher's holes are filled first
  (:func:`~vpp_service.matchers.fill_holes`) and ``*_nocc`` metrics are added
  when the frame has a non-occlusion mask. ``FusionResult.disparity`` is the
  matcher's output either way (holes not filled).

``FusionResult.timing_ms`` gets ``vpp`` (when VPP ran), ``match`` and
``process`` (the whole step) on top of the frame's own ``meta["timing_ms"]``.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Mapping
from dataclasses import replace

import numpy as np

from vpp_service.frame import FusionResult, StereoFrame
from vpp_service.matchers.base import Matcher
from vpp_service.matchers.depth_clip import DepthClip
from vpp_service.matchers.disparity_range import STEP, AutoRangeOptions, DisparityRange, MatcherCache
from vpp_service.metrics import answered_metrics, compute_metrics
from vpp_service.vpp import VPPConfig, depth_to_disparity, disparity_to_depth, project
from vpp_service.vpp.see_through import DepthFilter

#: The filter :func:`fuse` and :class:`Fusion` use unless told otherwise: ``auto`` with the default window.
DEFAULT_DEPTH_FILTER = DepthFilter()


def sparse_disparity(frame: StereoFrame) -> np.ndarray | None:
    """The frame's sparse disparity (converting metric depth when needed), or None.

    ``sparse_disparity`` wins over ``sensor_depth``; metric depth needs a
    calibration (without one the frame has no usable sparse points).
    """
    if frame.sparse_disparity is not None:
        return frame.sparse_disparity
    if frame.sensor_depth is not None and frame.calib is not None:
        c = frame.calib
        return depth_to_disparity(frame.sensor_depth, c.f, c.baseline, c.doffs)
    return None


def score(disparity: np.ndarray, frame: StereoFrame, protocol: bool = False) -> dict[str, float]:
    """Error of ``disparity`` against the frame's ground truth; ``{}`` without ground truth.

    Parameters
    ----------
    disparity : ndarray
        H x W float32 disparity of the frame's left view, NaN = invalid.
    frame : StereoFrame
        The frame (``gt_disparity``, ``nocc_mask``).
    protocol : bool
        Score as the evaluation protocol: fill the holes first and add
        ``*_nocc`` metrics when the frame has a mask. False: the raw output
        over all valid-GT pixels plus the three numbers every report shows,
        ``bad2_answered``, ``density`` and ``bad2_filled`` (what the service
        reports; see :mod:`vpp_service.metrics`).
    """
    if frame.gt_disparity is None:
        return {}
    from vpp_service.matchers.holes import fill_holes

    filled = fill_holes(disparity)
    if not protocol:
        raw = compute_metrics(disparity, frame.gt_disparity)
        bad2_filled = compute_metrics(filled, frame.gt_disparity, taus=(2.0,))["bad2"]
        return {**raw, **answered_metrics(raw), "bad2_filled": bad2_filled}
    out = compute_metrics(filled, frame.gt_disparity)
    if frame.nocc_mask is not None:
        for k, v in compute_metrics(filled, frame.gt_disparity, mask=frame.nocc_mask.astype(bool)).items():
            out[f"{k}_nocc"] = v
    return out


def fuse(
    frame: StereoFrame,
    matcher: Matcher,
    vpp_config: VPPConfig | None = None,
    *,
    seed: int = 0,
    guide: bool = False,
    depth: bool = True,
    protocol: bool = False,
    sparse: np.ndarray | None = None,
    depth_filter: DepthFilter | None = DEFAULT_DEPTH_FILTER,
    depth_clip: DepthClip | None = None,
    confidence: bool = False,
) -> FusionResult:
    """Process one frame: VPP (or guidance) on its sparse points, the matcher, depth and metrics.

    Parameters
    ----------
    frame : StereoFrame
        Rectified pair with optional sparse points, calibration and ground truth.
    matcher : Matcher
        A built matcher (:func:`vpp_service.matchers.build_matcher`).
    vpp_config : VPPConfig or None
        VPP settings; None disables VPP (plain or guided stereo).
    seed : int
        Seed of VPP's random pattern (used as given).
    guide : bool
        Pass the sparse points to the matcher as ``hints`` (guided stereo).
    depth : bool
        Compute metric depth when the frame is calibrated (skip it when unused).
    protocol : bool
        Score as the evaluation protocol (see :func:`score`).
    sparse : ndarray or None
        The frame's :func:`sparse_disparity` when the caller already has it
        (None: derived here when needed).
    depth_filter : DepthFilter or None
        The see-through filter and when it runs (default ``auto``: frames with
        ``meta["lidar_like"]``); None never filters.
    depth_clip : DepthClip or None
        The valid depth range: disparities outside it become NaN before depth
        and metrics; None (default) keeps the matcher's output as it is
        (what ``eval`` scores).
    confidence : bool
        Compute the per-pixel confidence (``FusionResult.confidence``); for
        matchers other than census-sgm a second matching pass.

    Returns
    -------
    FusionResult

    Raises
    ------
    TypeError, ValueError
        Invalid frame for the matcher/VPP (e.g. image narrower than the
        disparity range), ``guide`` with a matcher without guidance or a
        frame without sparse points.
    """
    timing: dict[str, float] = dict(frame.meta.get("timing_ms", {}))
    t_start = time.perf_counter()
    left, right = np.ascontiguousarray(frame.left), np.ascontiguousarray(frame.right)
    if sparse is None and (vpp_config is not None or guide):
        sparse = sparse_disparity(frame)
    see_through = None
    if sparse is not None and depth_filter is not None and depth_filter.applies(frame.meta):
        t0 = time.perf_counter()
        sparse, see_through = depth_filter(sparse)
        timing["depth_filter"] = (time.perf_counter() - t0) * 1e3
    left_vpp = right_vpp = occluded = None
    stats: dict[str, int] = {}
    m_left, m_right = left, right
    if vpp_config is not None and sparse is not None:
        t0 = time.perf_counter()
        res = project(left, right, sparse, vpp_config, seed=seed)
        timing["vpp"] = (time.perf_counter() - t0) * 1e3
        stats = res.stats.to_dict()
        # the kernel counted the usable points: no second pass over the map here
        if res.stats.given - res.stats.invalid > 0:
            left_vpp, right_vpp, occluded = res.left, res.right, res.occluded
            m_left, m_right = left_vpp, right_vpp
    hints = None
    if guide:
        if sparse is None:
            raise ValueError(f"guide: frame {frame.name or frame.seq!r} has no sparse points")
        hints = sparse
    t0 = time.perf_counter()
    conf = None
    if confidence:
        disp, conf = matcher.compute_with_confidence(m_left, m_right, hints=hints)
        disp = np.asarray(disp, dtype=np.float32)
    else:
        disp = np.asarray(matcher.compute(m_left, m_right, hints=hints), dtype=np.float32)
    timing["match"] = (time.perf_counter() - t0) * 1e3
    if depth_clip is not None:
        disp = depth_clip.apply(disp, matcher, frame.calib)
    if conf is not None:
        conf[np.isnan(disp)] = 0.0
    depth_map = None
    if depth and frame.calib is not None:
        c = frame.calib
        depth_map = np.asarray(disparity_to_depth(disp, c.f, c.baseline, c.doffs), dtype=np.float32)
    metrics = score(disp, frame, protocol)
    timing["process"] = (time.perf_counter() - t_start) * 1e3
    return FusionResult(
        frame=frame,
        disparity=disp,
        depth=depth_map,
        confidence=conf,
        left_vpp=left_vpp,
        right_vpp=right_vpp,
        occluded=occluded,
        vpp_stats=stats,
        timing_ms=timing,
        metrics=metrics,
        see_through=see_through,
    )


class Fusion:
    """The service's process stage: :func:`fuse` with a per-frame seed and counters.

    Parameters
    ----------
    matcher : Matcher
        A built matcher (:func:`vpp_service.matchers.build_matcher`).
    vpp_config : VPPConfig or None
        VPP settings; None disables VPP (plain stereo).
    seed : int
        Pattern seed; the frame's ``seq`` is added so every frame differs.
    depth : bool
        Compute metric depth (skip it when no sink uses it).
    disparity_range : AutoRangeOptions or None
        ``max_disparity = "auto"``: the range is derived per frame
        (:class:`~vpp_service.matchers.disparity_range.DisparityRange`) and the
        matcher for it is taken from a small cache built from ``matcher``'s type
        and options. None: ``matcher`` as given. Its ``limit`` is capped at the
        matcher's :attr:`~vpp_service.matchers.Matcher.max_range` (rounded down
        to a multiple of 16: a network's fixed range, 192 for PSMNet).
    depth_filter : DepthFilter or None
        The see-through filter (:func:`fuse`); the pipeline counts what it
        drops (``sparse.see_through``).
    depth_clip : DepthClip or None
        The valid depth range of every output (:func:`fuse`); the service
        always passes one (``[depth_clip]``, defaults from the matcher and the rig).
    confidence : bool
        Compute the per-pixel confidence (:func:`fuse`; only when a sink publishes it).

    Attributes
    ----------
    counters : dict
        ``vpp``: frames matched on a painted pair; ``no_depth``: frames
        without a usable point (with VPP disabled: without any positive
        finite point).
    """

    def __init__(
        self,
        matcher: Matcher,
        vpp_config: VPPConfig | None = None,
        seed: int = 0,
        depth: bool = True,
        disparity_range: AutoRangeOptions | None = None,
        *,
        depth_filter: DepthFilter | None = DEFAULT_DEPTH_FILTER,
        depth_clip: DepthClip | None = None,
        confidence: bool = False,
    ) -> None:
        if not isinstance(matcher, Matcher):
            raise TypeError(
                f"matcher must be a Matcher (vpp_service.matchers.build_matcher), got {type(matcher).__name__}"
            )
        if vpp_config is not None and not isinstance(vpp_config, VPPConfig):
            raise TypeError(f"vpp_config must be a VPPConfig or None, got {type(vpp_config).__name__}")
        if depth_filter is not None and not isinstance(depth_filter, DepthFilter):
            raise TypeError(f"depth_filter must be a DepthFilter or None, got {type(depth_filter).__name__}")
        if depth_clip is not None and not isinstance(depth_clip, DepthClip):
            raise TypeError(f"depth_clip must be a DepthClip or None, got {type(depth_clip).__name__}")
        self.depth_filter = depth_filter
        self.depth_clip = depth_clip
        self.matcher = matcher
        self.vpp_config = vpp_config
        self.seed = int(seed)
        self.depth = bool(depth)
        self.confidence = bool(confidence)
        self.counters = {"vpp": 0, "no_depth": 0}
        limit = matcher.max_range  # a network's fixed range caps "auto"
        if disparity_range is not None and limit is not None and disparity_range.limit > limit:
            disparity_range = replace(disparity_range, limit=max(STEP, limit // STEP * STEP))
        self.range = DisparityRange(disparity_range) if disparity_range is not None else None
        self._matchers = MatcherCache(matcher)
        self._lock = threading.Lock()

    @property
    def max_disparity(self) -> int | None:
        """The disparity range in use (the fixed one, or the last auto range; None before the first auto frame)."""
        return self.matcher.options.max_disparity if self.range is None else self.range.current

    def runtime(self) -> dict[str, object]:
        """The matcher's name, :meth:`~vpp_service.matchers.Matcher.runtime` and the range in use (``@status``)."""
        return {"name": self.matcher.name, **self.matcher.runtime(), "max_disparity": self.max_disparity}

    def prepare_next(self, frame: StereoFrame) -> None:
        """Build the random-pattern table the next frame (``seq + 1``) will use.

        The pipeline calls this after handing ``frame``'s result on, off the
        latency path: the table (65536 entries per channel, built per seed) is
        then already cached when that frame arrives instead of being built
        inside its VPP step.  Does nothing for other patterns.
        """
        cfg = self.vpp_config
        if cfg is None or cfg.pattern != "random":
            return
        from vpp_service.vpp.rng import kernel_table

        seed = self.seed + int(frame.seq) + 1
        if 0 <= seed < 2**64:
            kernel_table(seed, frame.left.shape[2] if frame.left.ndim == 3 else 1, (cfg.patch - 1) // 2)

    def network_status(self) -> Mapping[str, object] | None:
        """The matcher's remote servers' counters and states (a network on Triton), else None."""
        status = getattr(self.matcher, "network_status", None)
        return status() if callable(status) else None

    def __call__(self, frame: StereoFrame) -> FusionResult:
        """Process one frame (:func:`fuse` with seed ``seed + frame.seq``).

        Safe to call from several threads at once (frames in flight): the auto range is
        updated under a lock, in the order the calls take it.

        Raises
        ------
        TypeError, ValueError
            Invalid frame for the matcher/VPP (e.g. image narrower than the
            disparity range); the pipeline counts it as rejected.
        """
        matcher, sparse = self.matcher, None
        if self.range is not None:
            sparse = sparse_disparity(frame)
            with self._lock:
                matcher = self._matchers.get(self.range.update(sparse, frame.calib, frame.left.shape[1]))
        seed = self.seed + int(frame.seq)
        result = fuse(
            frame,
            matcher,
            self.vpp_config,
            seed=seed,
            depth=self.depth,
            sparse=sparse,
            depth_filter=self.depth_filter,
            depth_clip=self.depth_clip,
            confidence=self.confidence,
        )
        if result.left_vpp is not None:
            with self._lock:
                self.counters["vpp"] += 1
        elif self.vpp_config is not None or not _has_points(sparse if sparse is not None else sparse_disparity(frame)):
            with self._lock:
                self.counters["no_depth"] += 1
        return result


def _has_points(sparse: np.ndarray | None) -> bool:
    """True when the map has a positive finite point."""
    return sparse is not None and bool(np.any(np.isfinite(sparse) & (sparse > 0)))


__all__ = ["DEFAULT_DEPTH_FILTER", "Fusion", "fuse", "score", "sparse_disparity"]
