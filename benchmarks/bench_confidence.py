"""Benchmark of the per-pixel confidence: what ``compute_with_confidence`` costs over ``compute``.

Frames: a textured RGB pair of 1280 x 720 (720p) and of 1242 x 375 (KITTI), D = 128.
Matchers: ``census-sgm`` (8 paths, 1 thread and all threads; its confidence comes from
its own pass: the runner-up of each pixel's cost curve and the right WTA, in the row
finisher) and ``sgbm`` (OpenCV, 2 threads; its confidence is the left-right agreement
of a second pass on the mirrored pair). Each entry: the median time of ``compute`` and of
``compute_with_confidence`` over ``--reps`` runs after one warm-up, and the median of
their per-pair ratio (the two alternate, so both see the same machine state).

Prints a table and writes JSON (default ``out/benchmarks/bench_confidence.json``;
``--update-committed`` writes ``benchmarks/results/bench_confidence.json``).
"""

from __future__ import annotations

import argparse

import cv2
import numpy as np
from _harness import add_output_args, median_ms, output_path, paired_ratio, write_report

from vpp_service.matchers import Matcher, build_matcher
from vpp_service.threads import resolve_threads

SIZES = {"720p": (720, 1280), "kitti": (375, 1242)}
D = 128


def _pair(h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(0)
    base = cv2.GaussianBlur(rng.integers(0, 256, (h, w + D, 3), dtype=np.uint8), (3, 3), 0)
    return base[:, D:].copy(), base[:, D // 2 : D // 2 + w].copy()


def _times(m: Matcher, left: np.ndarray, right: np.ndarray, reps: int) -> tuple[float, float, float]:
    """Median ms of ``compute`` and of ``compute_with_confidence``, and their paired ratio."""

    def plain() -> object:
        return m.compute(left, right)

    def with_conf() -> object:
        return m.compute_with_confidence(left, right)

    return median_ms(plain, reps), median_ms(with_conf, reps), paired_ratio(with_conf, plain, reps)


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark (see the module docs)."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--reps", type=int, default=10, help="timed runs of each (default 10)")
    add_output_args(ap, "bench_confidence")
    a = ap.parse_args(argv)
    cv2.setNumThreads(2)
    all_threads = resolve_threads(None)
    matchers = [
        ("census-sgm", 1, {"threads": 1}),
        ("census-sgm", all_threads, {"threads": all_threads}),
        ("sgbm", 2, {}),
    ]
    rows: list[dict[str, object]] = []
    for size, (h, w) in SIZES.items():
        left, right = _pair(h, w)
        for name, threads, opts in matchers:
            plain, conf, ratio = _times(build_matcher(name, {"max_disparity": D, **opts}), left, right, a.reps)
            rows.append(
                {
                    "size": size,
                    "matcher": name,
                    "threads": threads,
                    "compute_ms": round(plain, 2),
                    "with_confidence_ms": round(conf, 2),
                    "ratio": round(ratio, 3),
                }
            )
    print("| size | matcher | threads | compute ms | with confidence ms | ratio (paired) |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['size']} | {r['matcher']} | {r['threads']} | {r['compute_ms']:.1f} | "
            f"{r['with_confidence_ms']:.1f} | {r['ratio']:.3f} |"
        )
    out = write_report(output_path(a, "bench_confidence"), rows, reps=a.reps, max_disparity=D)
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
