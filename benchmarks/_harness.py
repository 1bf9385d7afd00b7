"""What the benchmark scripts share: median timing of a call, the JSON report and where it goes.

Import from a script run as ``python benchmarks/<script>.py`` (the script's
folder is on ``sys.path``): ``from _harness import median_ms, write_report``.
Reports go to ``out/benchmarks/`` (ignored by git) unless ``--update-committed``
asks for the committed ``benchmarks/results/`` (see :func:`add_output_args`).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import numpy.typing as npt

REPO = Path(__file__).resolve().parents[1]
#: Where a benchmark writes its JSON by default: not committed (``out/`` is ignored by git).
SCRATCH = REPO / "out" / "benchmarks"
#: The committed results, overwritten only with ``--update-committed``.
COMMITTED = REPO / "benchmarks" / "results"


def add_output_args(ap: argparse.ArgumentParser, name: str) -> None:
    """Add ``--json PATH`` and ``--update-committed`` (resolved by :func:`output_path`) to ``ap``."""
    ap.add_argument(
        "--json",
        type=Path,
        help=f"write the JSON report here (default out/benchmarks/{name}.json, not committed)",
    )
    ap.add_argument(
        "--update-committed",
        action="store_true",
        help=f"overwrite the committed benchmarks/results/{name}.json instead",
    )


def output_path(a: argparse.Namespace, name: str) -> Path:
    """The report path: ``--json``, else the committed file with ``--update-committed``, else the scratch one."""
    if a.json is not None:
        return Path(a.json)
    return (COMMITTED if a.update_committed else SCRATCH) / f"{name}.json"


def _check_reps(reps: int) -> None:
    if isinstance(reps, bool) or not isinstance(reps, int) or reps < 1:
        raise ValueError(f"reps: must be an integer >= 1, got {reps!r}")


def times_ms(fn: Callable[[], object], reps: int) -> npt.NDArray[np.float64]:
    """Wall times of ``fn()`` in milliseconds, ``reps`` runs after one warm-up run.

    Parameters
    ----------
    fn : callable
        Zero-argument call to time (its result is discarded).
    reps : int
        Timed runs (>= 1).

    Returns
    -------
    numpy.ndarray
        ``reps`` float64 times in milliseconds, in the order they ran.
    """
    _check_reps(reps)
    fn()
    ts = []
    for _ in range(reps):
        t = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t)
    return np.asarray(ts, dtype=np.float64) * 1e3


def median_ms(fn: Callable[[], object], reps: int) -> float:
    """Median wall time of ``fn()`` in milliseconds over ``reps`` runs after one warm-up run.

    See :func:`times_ms` for the parameters.
    """
    return float(np.median(times_ms(fn, reps)))


def paired_ratio(fn: Callable[[], object], ref: Callable[[], object], reps: int) -> float:
    """Median over ``reps`` alternating runs of ``time(fn) / time(ref)``, after one warm-up each.

    Both calls see the same machine state (a shared VM drifts by tens of
    percent between a block of one and a block of the other).

    Parameters
    ----------
    fn : callable
        Zero-argument call to time.
    ref : callable
        Zero-argument reference call, run right before each run of ``fn``.
    reps : int
        Pairs of runs (>= 1).

    Returns
    -------
    float
        The median ratio.
    """
    _check_reps(reps)
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


def write_report(path: str | Path, rows: list[dict[str, object]], **meta: object) -> Path:
    """Write ``{"meta": {...}, "results": rows}`` as indented JSON; create the folder.

    Parameters
    ----------
    path : str or pathlib.Path
        File to write.
    rows : list of dict
        One JSON-serialisable mapping per result.
    **meta
        Added to ``meta``, which always has ``cpu_count`` and ``platform``.

    Returns
    -------
    pathlib.Path
        The path written.
    """
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    info = {"cpu_count": os.cpu_count(), "platform": platform.platform(), **meta}
    out.write_text(json.dumps({"meta": info, "results": rows}, indent=2))
    return out
