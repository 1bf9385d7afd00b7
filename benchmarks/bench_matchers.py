"""Benchmark of the stereo matchers: milliseconds per frame.

Frames: a textured RGB pair at Middlebury-third size 450x375 (D = 128) and
KITTI size 1242x375 (D = 192; 1241x376 in the data, rounded for OpenCV's
16-multiples it makes no difference). Matchers: ``sgbm`` (3-way), ``bm``,
``census-sgm`` with 8 and 4 paths, and ``census-sgm`` + guided stereo
(5 % hints). Census-SGM runs with 1 thread and with all threads; OpenCV uses
its own threading. Each entry is the median over ``--reps`` runs after one
warm-up run (the first call also pays page faults for the cost volumes).
Also reports the census-SGM stages at 1 thread. Prints a table and writes
JSON (default ``out/benchmarks/bench_matchers.json``; ``--update-committed`` writes
``benchmarks/results/bench_matchers.json``).
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Sequence
from functools import partial

import cv2
import numpy as np
from _harness import add_output_args, median_ms, output_path, write_report

from vpp_service.threads import configure_openmp, resolve_threads

SIZES = {"midd_third": (375, 450, 128), "kitti": (375, 1242, 192)}


#: One result row of the JSON report.
Row = dict[str, object]


def scene(H: int, W: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Smoothed-noise texture; right = left shifted by a smooth disparity field; 5 % hints."""
    rng = np.random.default_rng(seed)
    tex = cv2.GaussianBlur(rng.uniform(0, 255, (H, W + 96, 3)).astype(np.float32), (0, 0), 1.2)
    tex = np.clip((tex - tex.mean()) * 3 + 128, 0, 255).astype(np.uint8)
    gt = (20 + 30 * (1 + np.sin(np.arange(W) / 90.0)))[None, :].repeat(H, 0).astype(np.float32)
    left = np.ascontiguousarray(tex[:, :W])
    xs = (np.arange(W)[None, :] + 0.0).astype(np.float32).repeat(H, 0)
    # right(x') = left(x' + d): approximate with the left texture sampled at x' + gt
    map_x = xs + gt
    map_y = np.arange(H, dtype=np.float32)[:, None].repeat(W, 1)
    right = np.ascontiguousarray(cv2.remap(tex, map_x, map_y, cv2.INTER_LINEAR))
    hints = np.where(rng.random((H, W)) < 0.05, gt, np.nan).astype(np.float32)
    return left, right, hints


def matcher_rows(size: str, reps: int, all_threads: int) -> list[Row]:
    """Time every matcher on the ``size`` scene (census-SGM at 1 and all threads); print and return the rows."""
    from vpp_service.matchers import build_matcher

    H, W, D = SIZES[size]
    left, right, hints = scene(H, W)
    cases: list[tuple[str, dict[str, int], np.ndarray | None, int | None]] = [
        ("sgbm", {}, None, None),
        ("bm", {}, None, None),
    ]
    for n in sorted({1, all_threads}):
        cases += [
            ("census-sgm", {"threads": n}, None, n),
            ("census-sgm", {"threads": n, "paths": 4}, None, n),
            ("census-sgm", {"threads": n}, hints, n),
        ]
    rows: list[Row] = []
    for name, opts, h, t in cases:
        m = build_matcher(name, {"max_disparity": D, **opts})
        ms = median_ms(partial(m.compute, left, right, hints=h), reps)
        label = name + (f" paths={opts['paths']}" if "paths" in opts else "") + (" +guided" if h is not None else "")
        thr = "cv" if t is None else str(t)
        print(f"{size:11s} {W:4d}x{H:<4d} {D:4d} {label:22s} {thr:>4s} {ms:9.1f}")
        rows.append(
            {
                "size": size,
                "width": W,
                "height": H,
                "max_disparity": D,
                "matcher": name,
                "options": opts,
                "guided": h is not None,
                "threads": t,
                "ms": ms,
            }
        )
    return rows


def stage_rows(size: str, reps: int) -> list[Row]:
    """Time the census-SGM stages at 1 thread on the ``size`` scene; print and return the rows."""
    from vpp_service.matchers import census_sgm as cs
    from vpp_service.matchers.base import to_gray

    H, W, D = SIZES[size]
    left, right, _ = scene(H, W)
    gl, gr = to_gray(left), to_gray(right)
    cl, cr = cs.census_transform(gl, 1), cs.census_transform(gr, 1)
    cost = cs.hamming_cost_volume(cl, cr, D, 1)
    agg = cs.aggregate_costs(cost, gl, 8, threads=1)
    dl = cs.select_disparity(agg, threads=1)
    dr = cs.right_disparity(agg, 1)
    stages: dict[str, Callable[[], object]] = {
        "census x2": lambda: (cs.census_transform(gl, 1), cs.census_transform(gr, 1)),
        "hamming": lambda: cs.hamming_cost_volume(cl, cr, D, 1),
        "aggregate 8": lambda: cs.aggregate_costs(cost, gl, 8, threads=1),
        "aggregate 4": lambda: cs.aggregate_costs(cost, gl, 4, threads=1),
        "wta": lambda: cs.select_disparity(agg, threads=1),
        "right wta": lambda: cs.right_disparity(agg, 1),
        "lr check": lambda: cs.left_right_check(dl, dr, 1.0, 1),
        "median": lambda: cs.median_filter3x3(dl, 1),
    }
    rows: list[Row] = []
    for stage, fn in stages.items():
        ms = median_ms(fn, reps)
        print(f"{size:11s} {W:4d}x{H:<4d} {D:4d} {'  stage ' + stage:22s} {1:>4d} {ms:9.1f}")
        rows.append(
            {
                "size": size,
                "width": W,
                "height": H,
                "max_disparity": D,
                "matcher": "census-sgm",
                "stage": stage,
                "threads": 1,
                "ms": ms,
            }
        )
    return rows


def main(argv: Sequence[str] | None = None) -> int:
    """Run the benchmark (``--help`` for the options); write the JSON report."""
    ap = argparse.ArgumentParser(description=__doc__)
    add_output_args(ap, "bench_matchers")
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--quick", action="store_true", help="Middlebury size only, 3 reps")
    a = ap.parse_args(argv)
    configure_openmp()  # the service's OpenMP wait policy; before the kernels load
    reps = 3 if a.quick else a.reps
    allt = resolve_threads(None)
    sizes = ["midd_third"] if a.quick else list(SIZES)
    rows: list[Row] = []
    print(f"{'size':11s} {'WxH':>9s} {'D':>4s} {'matcher':22s} {'thr':>4s} {'ms':>9s}")
    for size in sizes:
        rows += matcher_rows(size, reps, allt)
        rows += stage_rows(size, reps)
    out = write_report(output_path(a, "bench_matchers"), rows, threads_all=allt, opencv=cv2.__version__, reps=reps)
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
