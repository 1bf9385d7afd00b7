"""What the benchmark scripts share: median timing of a call and the JSON report.

Import from a script run as ``python benchmarks/<script>.py`` (the script's
folder is on ``sys.path``): ``from _harness import median_ms, write_report``.
"""

from __future__ import annotations

import json
import os
import platform
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np


def times_ms(fn: Callable[[], Any], reps: int) -> np.ndarray:
    """Wall times of ``fn()`` in milliseconds, ``reps`` runs after one warm-up run.

    Parameters
    ----------
    fn : callable
        Zero-argument call to time.
    reps : int
        Timed runs (>= 1).
    """
    if isinstance(reps, bool) or not isinstance(reps, int) or reps < 1:
        raise ValueError(f"reps: must be an integer >= 1, got {reps!r}")
    fn()
    ts = []
    for _ in range(reps):
        t = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t)
    return np.asarray(ts) * 1e3


def median_ms(fn: Callable[[], Any], reps: int) -> float:
    """Median wall time of ``fn()`` in milliseconds over ``reps`` runs after one warm-up run
    (see :func:`times_ms`)."""
    return float(np.median(times_ms(fn, reps)))


def paired_ratio(fn: Callable[[], Any], ref: Callable[[], Any], reps: int) -> float:
    """Median over ``reps`` alternating runs of ``time(fn) / time(ref)``, after one warm-up each.

    Both calls see the same machine state (a shared VM drifts by tens of
    percent between a block of one and a block of the other).
    """
    if isinstance(reps, bool) or not isinstance(reps, int) or reps < 1:
        raise ValueError(f"reps: must be an integer >= 1, got {reps!r}")
    fn()
    ref()
    ratios = []
    for _ in range(reps):
        t0 = time.perf_counter()
        ref()
        t1 = time.perf_counter()
        fn()
        t2 = time.perf_counter()
        ratios.append((t2 - t1) / (t1 - t0))
    return float(np.median(ratios))


def write_report(path: str | Path, rows: list[dict[str, Any]], **meta: Any) -> Path:
    """Write ``{"meta": {...}, "results": rows}`` as indented JSON; create the folder.

    ``meta`` always gets ``cpu_count`` and ``platform``; keyword arguments add to it.
    Returns the path written.
    """
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    info = {"cpu_count": os.cpu_count(), "platform": platform.platform(), **meta}
    out.write_text(json.dumps({"meta": info, "results": rows}, indent=2))
    return out
