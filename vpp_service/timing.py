"""The one sliding window of durations: :class:`StageTimer` (mean, p50, p99, last per named stage).

The pipeline's per-stage timings and the sinks' own (encode, put, publish) use it;
durations are measured by the callers on a monotonic clock (``time.perf_counter``,
``time.monotonic_ns``), never on the wall clock.
"""

from __future__ import annotations

import threading
from collections import deque

import numpy as np


class StageTimer:
    """Sliding-window statistics (mean, p50, p99, last) of named durations in ms."""

    def __init__(self, window: int = 200) -> None:
        if window < 1:
            raise ValueError(f"window must be >= 1, got {window}")
        self.window = window
        self._data: dict[str, deque[float]] = {}
        self._lock = threading.Lock()

    def add(self, stage: str, ms: float) -> None:
        """Record one duration of ``stage``."""
        with self._lock:
            self._data.setdefault(stage, deque(maxlen=self.window)).append(float(ms))

    def summary(self) -> dict[str, dict[str, float]]:
        """``{stage: {mean, p50, p99, last, n}}``."""
        with self._lock:
            items = {k: np.array(v) for k, v in self._data.items() if v}
        out: dict[str, dict[str, float]] = {}
        for k, a in items.items():
            p50, p99 = np.percentile(a, [50, 99])  # one call: the same values as two, at half the cost
            out[k] = {
                "mean": float(a.mean()),
                "p50": float(p50),
                "p99": float(p99),
                "last": float(a[-1]),
                "n": int(a.size),
            }
        return out

    def medians(self) -> dict[str, float]:
        """``{stage: p50}`` of every stage with a sample (what the sinks report)."""
        return {k: v["p50"] for k, v in self.summary().items()}


__all__ = ["StageTimer"]
