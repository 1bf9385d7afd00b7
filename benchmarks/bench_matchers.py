"""Benchmark of the stereo matchers: milliseconds per frame.

Frames: a textured RGB pair at Middlebury-third size 450x375 and KITTI size
1242x375 (1241x376 in the data, rounded for OpenCV's 16-multiples it makes no
difference), both with D = 128. Matchers: ``sgbm`` (3-way), ``bm``,
``census-sgm`` with 8 and 4 paths, and ``census-sgm`` + guided stereo
(5 % hints). Census-SGM runs with 1 thread and with all threads; OpenCV uses
``cv2.setNumThreads(2)``. Each entry is the median over ``--reps`` runs after
one warm-up run (the matcher keeps its buffers, so only the warm-up pays the
page faults).

Head to head (KITTI, 8 paths): census-SGM on 1 and on 2 threads against
OpenCV SGBM 3-way on 2 threads, interleaved (one run of each per round, so
all three see the same machine state): medians, the interquartile range and
the per-round ratios (census-SGM 2 threads / SGBM, 1 thread / 2 threads).

Stages of census-SGM at 1 thread (KITTI), each kernel on buffers allocated
once, interleaved too: census of both images; the Hamming cost volume (the
matcher computes the costs inside the SGM passes, row by row, unless guided
stereo needs the volume); the 8-path aggregation from a stored volume and
with the costs computed in the passes; the SGM stage with the left
winner-takes-all, then also the right one and the left-right check, then
also the median (the steps' times are the per-round differences: the stage
finishes each row while it is in cache; with uint8 partial sums and D <= 128,
the AVX2 build's stage runs both WTAs on 16-bit keys); and the plain WTA,
left-right check and median kernels alone on stored volumes / maps.

The deep matcher (``--part deep``, opt-in: it needs the model and an engine,
``pip install -e ".[deep]"``): ``psmnet`` with ``--model`` (default
``../shared/models/psmnet_kitti2015.onnx``) on the KITTI-size pair (padded to
1248 x 384), ``--deep-threads`` threads (default 2), f32 (``--precision``
adds others, e.g. ``bf16``), ``--device`` (``cuda`` on a GPU machine): seconds
per frame (median of ``--deep-reps`` after one warm-up), the share of the
network's time spent before (tensors) and after it (crop, range check), and
the process's peak RSS after the runs.

Prints tables and writes JSON (default ``out/benchmarks/bench_matchers.json``;
``--update-committed`` writes ``benchmarks/results/bench_matchers.json``).
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable, Sequence
from functools import partial

import cv2
import numpy as np
from _harness import REPO, add_output_args, median_ms, output_path, write_report

from vpp_service.threads import configure_openmp, resolve_threads

SIZES = {"midd_third": (375, 450, 128), "kitti": (375, 1242, 128)}
#: OpenCV's threads (the head-to-head compares with 2).
CV_THREADS = 2


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


def interleaved_ms(calls: dict[str, Callable[[], object]], reps: int) -> dict[str, np.ndarray]:
    """Wall times (ms) of each call, ``reps`` rounds of one run each in turn, after one warm-up run each."""
    for fn in calls.values():
        fn()
    out: dict[str, list[float]] = {k: [] for k in calls}
    for _ in range(reps):
        for k, fn in calls.items():
            t = time.perf_counter()
            fn()
            out[k].append((time.perf_counter() - t) * 1e3)
    return {k: np.asarray(v) for k, v in out.items()}


def spread(ts: np.ndarray) -> dict[str, float]:
    """Median, quartiles and extremes of ``ts``."""
    q1, med, q3 = np.percentile(ts, [25, 50, 75])
    return {"ms": float(med), "p25": float(q1), "p75": float(q3), "min": float(ts.min()), "max": float(ts.max())}


def versus_rows(reps: int) -> list[Row]:
    """Census-SGM (8 paths) on 1 and 2 threads vs OpenCV SGBM 3-way on 2 threads, KITTI, interleaved."""
    from vpp_service.matchers import build_matcher

    H, W, D = SIZES["kitti"]
    left, right, _ = scene(H, W)
    m1 = build_matcher("census-sgm", {"max_disparity": D, "threads": 1})
    m2 = build_matcher("census-sgm", {"max_disparity": D, "threads": 2})
    sgbm = build_matcher("sgbm", {"max_disparity": D})
    ts = interleaved_ms(
        {
            "sgbm 3-way, 2 thr": partial(sgbm.compute, left, right),
            "census-sgm, 1 thr": partial(m1.compute, left, right),
            "census-sgm, 2 thr": partial(m2.compute, left, right),
        },
        reps,
    )
    rows: list[Row] = []
    print(f"\nKITTI {W}x{H}, D = {D}, 8 paths, interleaved, {reps} rounds")
    print(f"{'':22s} {'median':>8s} {'p25':>8s} {'p75':>8s} {'min':>8s} {'max':>8s}")
    for k, v in ts.items():
        st = spread(v)
        print(f"{k:22s} {st['ms']:8.1f} {st['p25']:8.1f} {st['p75']:8.1f} {st['min']:8.1f} {st['max']:8.1f}")
        rows.append({"size": "kitti", "width": W, "height": H, "max_disparity": D, "versus": k, **st})
    ratio = ts["census-sgm, 2 thr"] / ts["sgbm 3-way, 2 thr"]
    speedup = ts["census-sgm, 1 thr"] / ts["census-sgm, 2 thr"]
    for name, r in (("census-sgm 2 thr / sgbm", ratio), ("census-sgm 1 thr / 2 thr", speedup)):
        q1, med, q3 = np.percentile(r, [25, 50, 75])
        print(f"{name:26s} median {med:5.2f}  (p25 {q1:5.2f}, p75 {q3:5.2f}), per round")
        rows.append({"size": "kitti", "ratio": name, "median": float(med), "p25": float(q1), "p75": float(q3)})
    return rows


def stage_rows(reps: int) -> list[Row]:
    """Time the census-SGM kernels at 1 thread on the KITTI scene, on buffers allocated once; print, return rows."""
    from vpp_service.matchers import census_sgm as cs
    from vpp_service.matchers.inputs import to_gray

    k = cs._k  # the build in use
    H, W, D = SIZES["kitti"]
    left, right, _ = scene(H, W)
    gl, gr = to_gray(left), to_gray(right)
    o = cs.CensusSGMOptions(max_disparity=D)
    lut = cs.p2_table(o.p1, o.p2_min, o.p2_alpha, o.p2_gamma)
    ws = cs.SGMWorkspace(H, W, D, 1)
    cost = np.empty((H, W, D), np.uint16)
    k.cost_stage(ws, gl, gr, cost, cs.INVALID_COST, 1)
    dl, dr, lr, out = (np.empty((H, W), np.float32) for _ in range(4))
    agg = cs.aggregate_costs(cost, gl, 8, threads=1)
    k.winner_takes_all(agg, dl, o.uniqueness, o.subpixel, 1)
    k.right_disparity(agg, dr, 1)
    k.left_right_check(dl, dr, lr, o.lr_tolerance, 1)

    def sgm(*, volume: bool, wta: bool = True, lr_check: bool = True, median: bool = True) -> Callable[[], None]:
        params = cs.stage_params(o, wta=wta)
        params["lr_check"], params["median"] = lr_check, median

        def run() -> None:
            k.sgm_stage(params, lut, ws, cost if volume else None, gl, None, out, 1)

        return run

    stages: dict[str, Callable[[], object]] = {
        "census x2": lambda: k.cost_stage(ws, gl, gr, None, cs.INVALID_COST, 1),
        "cost volume": lambda: k.hamming_volume(ws.cl, ws.cr, cost, cs.INVALID_COST, 1),
        "aggregation 8": sgm(volume=True, wta=False),
        "aggregation 8 + costs": sgm(volume=False, wta=False),
        "+ wta left": sgm(volume=False, lr_check=False, median=False),
        "+ wta right, lr": sgm(volume=False, median=False),
        "+ median": sgm(volume=False),
        "wta left (volume)": lambda: k.winner_takes_all(agg, dl, o.uniqueness, o.subpixel, 1),
        "wta right (volume)": lambda: k.right_disparity(agg, dr, 1),
        "lr check": lambda: k.left_right_check(dl, dr, lr, o.lr_tolerance, 1),
        "median": lambda: k.median3x3(lr, out, 1),
    }
    ts = interleaved_ms(stages, reps)
    keyed = k.keyed_wta(8, lut, False, D)  # the stage's WTAs on 16-bit keys; the "(volume)" rows: plain kernels
    print(
        f"\ncensus-sgm stages, KITTI {W}x{H}, D = {D}, 1 thread, {'AVX2' if k.AVX2 else 'portable'} build, "
        f"WTA in the SGM stage on {'keys' if keyed else 'costs'}"
    )
    rows: list[Row] = []
    for stage, v in ts.items():
        st = spread(v)
        print(f"  {stage:28s} {st['ms']:8.1f} ms  (p25 {st['p25']:.1f}, p75 {st['p75']:.1f})")
        rows.append(
            {
                "size": "kitti",
                "width": W,
                "height": H,
                "max_disparity": D,
                "matcher": "census-sgm",
                "stage": stage,
                "threads": 1,
                "avx2": bool(k.AVX2),
                "keyed_wta": keyed,
                **st,
            }
        )
    # the SGM stage's steps as it runs them (rows finished in cache): per-round differences
    steps = {
        "wta left, in sgm": ts["+ wta left"] - ts["aggregation 8 + costs"],
        "wta both views + lr, in sgm": ts["+ wta right, lr"] - ts["aggregation 8 + costs"],
        "median, in sgm": ts["+ median"] - ts["+ wta right, lr"],
    }
    for stage, v in steps.items():
        med = float(np.median(v))
        print(f"  {stage:28s} {med:8.1f} ms  (difference per round)")
        rows.append({"size": "kitti", "matcher": "census-sgm", "stage": stage, "threads": 1, "ms": med})
    return rows


def deep_rows(model: str, reps: int, threads: int, precisions: Sequence[str], device: str) -> list[Row]:
    """Time ``psmnet`` on the KITTI-size pair per precision; print and return the rows."""
    import resource

    from vpp_service.matchers import build_matcher

    H, W, _ = SIZES["kitti"]
    left, right, _ = scene(H, W)
    rows: list[Row] = []
    title = f"deep matcher (KITTI {W}x{H})"
    print(f"\n{title:34s} {'s/frame':>8s} {'pre+post/net':>13s} {'peak RSS':>9s}")
    for precision in precisions:
        opts = {"model": model, "threads": threads, "precision": precision, "device": device, "max_disparity": 192}
        m = build_matcher("psmnet", opts)
        m.compute(left, right)  # warm-up: opens the engine, compiles the graph for this size
        total, pre, net, post = [], [], [], []
        for _ in range(reps):
            t0 = time.perf_counter()
            m.compute(left, right)
            total.append(time.perf_counter() - t0)
            t = m.last_timing
            pre.append(t["pre"])
            net.append(t["network"])
            post.append(t["post"])
        rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux: kB
        share = float(np.median((np.array(pre) + np.array(post)) / np.array(net)))
        eng = m.engine()
        row: Row = {
            "part": "deep",
            "matcher": "psmnet",
            "size": "kitti",
            "W": W,
            "H": H,
            "engine": eng.kind,
            "device": eng.device,
            "precision": eng.precision,
            "threads": eng.threads,
            "s_per_frame": float(np.median(total)),
            "s_per_frame_iqr": [float(np.percentile(total, 25)), float(np.percentile(total, 75))],
            "fps": 1.0 / float(np.median(total)),
            "network_ms": float(np.median(net)),
            "pre_ms": float(np.median(pre)),
            "post_ms": float(np.median(post)),
            "pre_post_share": share,
            "peak_rss_mb": rss_mb,
            "reps": reps,
        }
        rows.append(row)
        label = f"psmnet {eng.describe()}"
        print(f"{label:34s} {row['s_per_frame']:8.2f} {100 * share:12.2f}% {rss_mb:7.0f} MB")
    return rows


def main(argv: Sequence[str] | None = None) -> int:
    """Run the benchmark (``--help`` for the options); write the JSON report."""
    ap = argparse.ArgumentParser(description=__doc__)
    add_output_args(ap, "bench_matchers")
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--versus-reps", type=int, default=15, help="rounds of the interleaved head to head")
    ap.add_argument("--quick", action="store_true", help="Middlebury size only, 3 reps, no head to head")
    ap.add_argument(
        "--part",
        choices=("all", "versus", "stages", "deep"),
        default="all",
        help="run only the head to head, the stages, or the deep matcher (deep runs only when asked)",
    )
    ap.add_argument("--model", default=str(REPO.parent / "shared" / "models" / "psmnet_kitti2015.onnx"))
    ap.add_argument("--deep-threads", type=int, default=2, help="the network's CPU threads (default 2)")
    ap.add_argument("--deep-reps", type=int, default=3, help="timed runs of the network after the warm-up")
    ap.add_argument("--precision", action="append", default=None, help="f32 (default), bf16, f16; repeatable")
    ap.add_argument("--device", default="cpu", choices=("auto", "cpu", "cuda"), help="where the network runs")
    a = ap.parse_args(argv)
    configure_openmp()  # the service's OpenMP wait policy; before the kernels load
    cv2.setNumThreads(CV_THREADS)
    reps = 3 if a.quick else a.reps
    allt = resolve_threads(None)
    sizes = ["midd_third"] if a.quick else list(SIZES)
    rows: list[Row] = []
    if a.part == "deep":
        rows = deep_rows(a.model, a.deep_reps, a.deep_threads, a.precision or ["f32"], a.device)
        out = write_report(output_path(a, "bench_matchers_deep"), rows, model=a.model)
        print(f"wrote {out}")
        return 0
    print(f"{'size':11s} {'WxH':>9s} {'D':>4s} {'matcher':22s} {'thr':>4s} {'ms':>9s}")
    if a.part == "all":
        for size in sizes:
            rows += matcher_rows(size, reps, allt)
    if not a.quick and a.part in ("all", "versus"):
        rows += versus_rows(a.versus_reps)
    if not a.quick and a.part in ("all", "stages"):
        rows += stage_rows(max(reps, 7))
    out = write_report(
        output_path(a, "bench_matchers"),
        rows,
        threads_all=allt,
        opencv=cv2.__version__,
        opencv_threads=CV_THREADS,
        reps=reps,
    )
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
