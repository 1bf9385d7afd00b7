"""The per-frame processing step: sparse depth -> VPP -> matcher -> depth, metrics.

:class:`Fusion` is what the pipeline's process stage calls on every frame.
A frame with metric depth (``sensor_depth``) and a calibration has it converted
to disparity (``d = f * b / Z - doffs``); a frame without a usable point
(none with ``0 < d < width``, as counted by VPP itself) runs the matcher on the
raw pair and is counted as ``no_depth`` (with VPP disabled, frames without any
positive finite point are). When the frame carries ground truth, ``FusionResult.metrics``
holds the error against it (:func:`vpp_service.evaluation.metrics.compute_metrics`).
"""
from __future__ import annotations

import dataclasses
import time
from typing import Any

import numpy as np

from vpp_service.frame import FusionResult, StereoFrame
from vpp_service.vpp import depth_to_disparity


class Fusion:
    """Callable processing one :class:`StereoFrame` into a :class:`FusionResult`.

    Parameters
    ----------
    matcher : Matcher
        A built matcher (``vpp_service.matchers.build_matcher``).
    vpp_config : VPPConfig or None
        VPP settings; None disables VPP (plain stereo).
    seed : int
        Pattern seed; the frame's ``seq`` is added so every frame differs.
    depth : bool
        Compute metric depth (skip it when no sink uses it).
    """

    def __init__(self, matcher: Any, vpp_config: Any = None, seed: int = 0, depth: bool = True) -> None:
        if not hasattr(matcher, "compute"):
            raise TypeError(f"matcher must have a compute(left, right) method, got {type(matcher).__name__}")
        self.matcher = matcher
        self.vpp_config = vpp_config
        self.seed = int(seed)
        self.depth = bool(depth)
        self.counters = {"vpp": 0, "no_depth": 0}

    @staticmethod
    def sparse_disparity(frame: StereoFrame) -> np.ndarray | None:
        """The frame's sparse disparity (converting metric depth when needed), or None."""
        if frame.sparse_disparity is not None:
            return frame.sparse_disparity
        if frame.sensor_depth is not None and frame.calib is not None:
            c = frame.calib
            return depth_to_disparity(frame.sensor_depth, c.f, c.baseline, c.doffs)
        return None

    def prepare_next(self, frame: StereoFrame) -> None:
        """Build the random-pattern table the next frame (``seq + 1``) will use.

        The pipeline calls this after handing ``frame``'s result on, off the
        latency path: the table (65536 entries per channel, built per seed) is
        then already cached when that frame arrives, instead of costing about
        0.1-0.2 ms inside its VPP step.  Does nothing for other patterns.
        """
        cfg = self.vpp_config
        if cfg is None or getattr(cfg, "pattern", None) != "random":
            return
        from vpp_service.vpp.rng import kernel_table

        seed = self.seed + int(frame.seq) + 1
        if 0 <= seed < 2 ** 64:
            kernel_table(seed, frame.left.shape[2] if frame.left.ndim == 3 else 1, (cfg.patch - 1) // 2)

    def __call__(self, frame: StereoFrame) -> FusionResult:
        """Process one frame.

        Raises
        ------
        TypeError, ValueError
            Invalid frame for the matcher/VPP (e.g. image narrower than the
            disparity range); the pipeline counts it as rejected.
        """
        timing: dict[str, float] = dict(frame.meta.get("timing_ms", {}))
        t_start = time.perf_counter()
        left, right = np.ascontiguousarray(frame.left), np.ascontiguousarray(frame.right)
        sparse = self.sparse_disparity(frame)
        left_vpp = right_vpp = occluded = None
        stats: dict[str, Any] = {}
        m_left, m_right = left, right
        if self.vpp_config is not None and sparse is not None:
            from vpp_service.vpp import project

            t0 = time.perf_counter()
            res = project(left, right, sparse, self.vpp_config, seed=self.seed + int(frame.seq))
            timing["vpp"] = (time.perf_counter() - t0) * 1e3
            raw_stats = getattr(res, "stats", None)
            if dataclasses.is_dataclass(raw_stats):
                stats = dataclasses.asdict(raw_stats)
            elif isinstance(raw_stats, dict):
                stats = dict(raw_stats)
            # the kernel counted the usable points: no second pass over the map here
            if stats.get("given", 0) - stats.get("invalid", 0) > 0:
                left_vpp, right_vpp, occluded = res.left, res.right, res.occluded
                self.counters["vpp"] += 1
                m_left, m_right = left_vpp, right_vpp
            else:
                self.counters["no_depth"] += 1
        elif sparse is None or not np.any(np.isfinite(sparse) & (sparse > 0)):
            self.counters["no_depth"] += 1
        t0 = time.perf_counter()
        disp = np.asarray(self.matcher.compute(m_left, m_right), dtype=np.float32)
        timing["match"] = (time.perf_counter() - t0) * 1e3
        depth = None
        if self.depth and frame.calib is not None:
            from vpp_service.vpp import disparity_to_depth

            c = frame.calib
            depth = np.asarray(disparity_to_depth(disp, c.f, c.baseline, c.doffs), dtype=np.float32)
        metrics: dict[str, float] = {}
        if frame.gt_disparity is not None:
            from vpp_service.evaluation.metrics import compute_metrics

            metrics = {k: float(v) for k, v in compute_metrics(disp, frame.gt_disparity).items()}
        timing["process"] = (time.perf_counter() - t_start) * 1e3
        return FusionResult(frame=frame, disparity=disp, depth=depth, left_vpp=left_vpp, right_vpp=right_vpp,
                            occluded=occluded, vpp_stats=stats, timing_ms=timing, metrics=metrics)


__all__ = ["Fusion"]
