"""See-through points of a LiDAR beside the camera, and what the see-through filter does about them.

For each shared scene (KITTI 2012 000070 and the Middlebury 2005/06 third-size
scenes, read in place from ``<repo>/../shared/data``), a LiDAR is simulated
(:class:`vpp_service.sources.sensors.LidarSensor`, seed 0) twice:

* **no offset** - at the left camera centre, cast against the same z-buffered
  surface as the offset one (``zbuffer = true``: the same density and beams);
* **offset** - at ``pose`` (default ``kitti``: 0.27 m behind, 0.075 m above the
  left camera), so the returns it sees past foreground edges land on foreground
  pixels with background depth.

Reported per scene: the projected points and those with ground truth; the
**see-through share** (points more than 1 px *behind* the ground truth of their
pixel, i.e. disparity < GT - 1, over the points with ground truth; points more
than 1 px in front of it are edge pixels, there with or without the offset,
and counted apart as ``in_front``); the filter's
**precision** (see-through among the dropped points with ground truth),
**recall** (dropped among the see-through points) and **good kept** (kept
among the points within 1 px); and VPP's bad-2 (census-sgm, the paper's
protocol: holes filled, all valid-GT pixels) with no offset, offset unfiltered
and offset filtered (:func:`vpp_service.evaluation.run_evaluation`,
``depth_filter`` none / see-through; VPP's defaults, ``--occlusion`` changes its
occlusion strategy, e.g. ``off`` to see the points' harm without VPP's own
occlusion handling). **Recovered** = (unfiltered - filtered)
/ (unfiltered - no offset): the share of the accuracy the offset costs that the
filter wins back (means over the Middlebury scenes are of the per-scene bad-2).
**Oracle filter**: bad-2 with exactly the see-through points removed, the bound
of a see-through filter (the offset also moves and hides points, which no
filter gives back).

Geometry: KITTI has its calibration. Middlebury ships none; its scenes get the
2005/06 rig's nominal geometry at third size (f = 3740 / 3 px, baseline
0.16 m, doffs 0: depths 2.5 - 10 m) and a LiDAR whose 64 beams span the
camera's vertical field of view (+-8.5 degrees), azimuth step 0.2 degrees.

Cost: the filter on a KITTI-size map (the KITTI frame, 1241 x 376) holding
120k points (drawn from its ground-truth pixels, seed 0), one thread,
interleaved with a copy of the map as the reference, median and minimum over
``--reps`` runs.

Output: a table on stdout and JSON in ``out/benchmarks/bench_see_through.json``
(not committed; ``--json`` elsewhere).
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace

import numpy as np
from _harness import REPO, add_output_args, output_path, write_report

from vpp_service.datasets import open_dataset
from vpp_service.evaluation import run_evaluation
from vpp_service.frame import StereoFrame
from vpp_service.service.allocator import reuse_freed_memory
from vpp_service.sources.sensors import LidarSensor, build_sensor
from vpp_service.vpp import VPPConfig
from vpp_service.vpp.see_through import DepthFilter

SHARED = REPO.parent / "shared" / "data"
KITTI = SHARED / "kitti2012_training"
MIDDLEBURY = SHARED / "middlebury2005_2006_thirdsize"
#: Middlebury 2005/06 at third size: f = 3740 / 3 px, baseline 160 mm; the beams span the vertical FOV.
MIDDLEBURY_LIDAR = {"nominal_f": 3740.0 / 3.0, "nominal_baseline": 0.16, "fov_up": 8.5, "fov_down": -8.5}


def classify(frame: StereoFrame, sparse: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Masks of the points with ground truth: see-through (> 1 px behind it), in front (> 1 px), good (within 1 px)."""
    gt = frame.gt_disparity
    assert gt is not None
    scored = np.isfinite(sparse) & np.isfinite(gt)
    err = np.where(scored, sparse - np.where(np.isfinite(gt), gt, 0), 0)
    behind, front = scored & (err < -1.0), scored & (err > 1.0)
    return behind, front, scored & ~behind & ~front


def see_through_stats(frame: StereoFrame, sparse: np.ndarray, depth_filter: DepthFilter) -> dict[str, float]:
    """Points, see-through share and the filter's precision / recall / good kept, against the ground truth."""
    bad, front, good = classify(frame, sparse)
    have = np.isfinite(sparse)
    scored = bad | front | good
    kept, dropped_n = depth_filter(sparse)
    dropped = have & ~np.isfinite(kept)
    n_bad, n_good = int(bad.sum()), int(good.sum())
    dropped_scored = int((dropped & scored).sum())
    return {
        "points": int(have.sum()),
        "scored": int(scored.sum()),
        "see_through": n_bad,
        "see_through_pct": 100.0 * n_bad / max(1, int(scored.sum())),
        "in_front": int(front.sum()),
        "dropped": dropped_n,
        "precision": float((dropped & bad).sum() / dropped_scored) if dropped_scored else float("nan"),
        "recall": float((dropped & bad).sum() / n_bad) if n_bad else float("nan"),
        "good_kept": float((good & ~dropped).sum() / n_good) if n_good else float("nan"),
    }


def bad2(frame: StereoFrame, sensor: LidarSensor, mode: str, depth_filter: DepthFilter, vpp: VPPConfig) -> float:
    """VPP + census-sgm bad-2 (%) of one scene with this sensor and filter mode."""
    f = replace(depth_filter, mode=mode)
    rows = run_evaluation(frame, "census-sgm", ["vpp"], None, sensor, vpp_config=vpp, seed=0, depth_filter=f)
    return float(rows[0]["bad2"])  # type: ignore[arg-type]


def scene_row(
    dataset: str, frame: StereoFrame, opts: dict[str, object], pose: object, *, filt: DepthFilter, vpp: VPPConfig
) -> dict[str, object]:
    """Every number of one scene (see the module docs)."""
    centre = build_sensor("lidar", {**opts, "zbuffer": True})
    offset = build_sensor("lidar", {**opts, "pose": pose})
    assert isinstance(centre, LidarSensor) and isinstance(offset, LidarSensor)
    sparse = offset.simulate(frame, 0).sparse_disparity
    assert sparse is not None
    row: dict[str, object] = {"dataset": dataset, "scene": frame.name, **see_through_stats(frame, sparse, filt)}
    # the bound of a see-through filter: exactly the see-through points removed
    oracle = np.where(classify(frame, sparse)[0], np.nan, sparse).astype(np.float32)
    rows = run_evaluation(
        frame.with_(sparse_disparity=oracle), "census-sgm", ["vpp"], None, "frame", vpp_config=vpp, depth_filter=None
    )
    row["bad2_offset_oracle"] = float(rows[0]["bad2"])  # type: ignore[arg-type]
    row["bad2_no_offset"] = bad2(frame, centre, "none", filt, vpp)
    row["bad2_offset"] = bad2(frame, offset, "none", filt, vpp)
    row["bad2_offset_filtered"] = bad2(frame, offset, "see-through", filt, vpp)
    row["bad2_no_offset_filtered"] = bad2(frame, centre, "see-through", filt, vpp)
    return row


def recovered(unfiltered: float, filtered: float, no_offset: float) -> float:
    """Share of the accuracy lost to the offset that the filter wins back (NaN when nothing was lost)."""
    lost = unfiltered - no_offset
    return (unfiltered - filtered) / lost if lost > 0 else float("nan")


def filter_cost(reps: int, filt: DepthFilter) -> dict[str, float]:
    """Median / min ms of the filter on 120k KITTI ground-truth points (1241 x 376), interleaved with a copy."""
    frame = open_dataset("auto", KITTI)[0]
    gt = frame.gt_disparity
    assert gt is not None
    rng = np.random.default_rng(0)
    valid = np.flatnonzero(np.isfinite(gt))
    pick = rng.choice(valid, size=min(120_000, valid.size), replace=False)
    sparse = np.full(gt.shape, np.nan, np.float32)
    sparse.flat[pick] = gt.flat[pick]
    copy = np.empty_like(sparse)
    t_filter, t_copy = [], []
    filt(sparse)
    for _ in range(reps):
        t = time.perf_counter()
        np.copyto(copy, sparse)
        t_copy.append(time.perf_counter() - t)
        t = time.perf_counter()
        filt(sparse)
        t_filter.append(time.perf_counter() - t)
    return {
        "points": int(pick.size),
        "shape": f"{gt.shape[1]}x{gt.shape[0]}",
        "filter_ms_median": float(np.median(t_filter) * 1e3),
        "filter_ms_min": float(np.min(t_filter) * 1e3),
        "copy_ms_median": float(np.median(t_copy) * 1e3),
    }


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark (see the module docs)."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--pose", default="kitti", help="LiDAR pose: a preset name or tx,ty,tz in metres (default kitti)")
    ap.add_argument("--scenes", help="comma list of Middlebury scenes (default all)")
    ap.add_argument("--no-kitti", action="store_true", help="skip KITTI")
    ap.add_argument("--reps", type=int, default=300, help="timed runs of the filter (default 300)")
    ap.add_argument(
        "--occlusion",
        default="fgd",
        choices=("fgd", "no", "bkgd", "off"),
        help="VPP's occlusion strategy (default fgd, VPP's default)",
    )
    for key in ("window_w", "window_h"):
        ap.add_argument(f"--{key.replace('_', '-')}", type=int, default=getattr(DepthFilter(), key))
    for key in ("margin", "min_gap"):
        ap.add_argument(f"--{key.replace('_', '-')}", type=float, default=getattr(DepthFilter(), key))
    add_output_args(ap, "bench_see_through")
    a = ap.parse_args(argv)
    if not SHARED.is_dir():
        print(f"shared data not found at {SHARED}: see its README.md", file=sys.stderr)
        return 2
    reuse_freed_memory()
    pose: object = a.pose if "," not in a.pose else [float(v) for v in a.pose.split(",")]
    filt = DepthFilter(mode="see-through", window_w=a.window_w, window_h=a.window_h, margin=a.margin, min_gap=a.min_gap)
    vpp = VPPConfig(occlusion=a.occlusion)
    rows: list[dict[str, object]] = []
    if not a.no_kitti:
        rows.append(scene_row("kitti2012", open_dataset("auto", KITTI)[0], {}, pose, filt=filt, vpp=vpp))
        print(_line(rows[-1]), flush=True)
    mb = open_dataset("auto", MIDDLEBURY)
    mb.select([s.strip() for s in a.scenes.split(",")] if a.scenes else None, None)
    for i in range(len(mb)):
        rows.append(scene_row("middlebury2005_2006", mb[i], MIDDLEBURY_LIDAR, pose, filt=filt, vpp=vpp))
        print(_line(rows[-1]), flush=True)
    summary = _summary(rows)
    cost = filter_cost(a.reps, filt)
    print(_table(summary, cost))
    out = write_report(
        output_path(a, "bench_see_through"),
        rows,
        pose=pose,
        occlusion=a.occlusion,
        filter={k: getattr(filt, k) for k in ("window_w", "window_h", "margin", "min_gap")},
        summary=summary,
        cost=cost,
    )
    print(f"json: {out}")
    return 0


def _summary(rows: list[dict[str, object]]) -> dict[str, dict[str, float]]:
    """Per dataset: sums of the point counts, means of the per-scene shares and bad-2, the recovered share."""
    out: dict[str, dict[str, float]] = {}
    for ds in dict.fromkeys(str(r["dataset"]) for r in rows):
        sel = [r for r in rows if r["dataset"] == ds]

        def mean(key: str, sel: list[dict[str, object]] = sel) -> float:
            return float(np.nanmean([float(r[key]) for r in sel]))  # type: ignore[arg-type]

        s = {k: mean(k) for k in ("see_through_pct", "precision", "recall", "good_kept")}
        s |= {
            k: mean(k)
            for k in (
                "bad2_no_offset",
                "bad2_offset",
                "bad2_offset_filtered",
                "bad2_no_offset_filtered",
                "bad2_offset_oracle",
            )
        }
        s["recovered"] = recovered(s["bad2_offset"], s["bad2_offset_filtered"], s["bad2_no_offset"])
        s["recovered_oracle"] = recovered(s["bad2_offset"], s["bad2_offset_oracle"], s["bad2_no_offset"])
        s["scenes"] = float(len(sel))
        s["points"] = float(sum(int(r["points"]) for r in sel))  # type: ignore[call-overload]
        out[ds] = s
    return out


def _line(r: dict[str, object]) -> str:
    return (
        f"{r['dataset']:<20} {r['scene']:<18} pts {r['points']:>6} see-through {r['see_through_pct']:5.1f} % "
        f"prec {r['precision']:.2f} rec {r['recall']:.2f} good kept {r['good_kept']:.3f} | bad-2 "
        f"{r['bad2_no_offset']:.2f} / {r['bad2_offset']:.2f} / {r['bad2_offset_filtered']:.2f}"
    )


def _table(summary: dict[str, dict[str, float]], cost: dict[str, float]) -> str:
    head = (
        "| dataset | scenes | see-through % | precision | recall | good kept | bad-2 no offset | "
        "offset | offset + filter | recovered | oracle filter | oracle recovered |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|---|"
    )
    lines = [
        f"| {ds} | {s['scenes']:.0f} | {s['see_through_pct']:.1f} | {s['precision']:.2f} | {s['recall']:.2f} | "
        f"{100 * s['good_kept']:.1f} % | {s['bad2_no_offset']:.2f} | {s['bad2_offset']:.2f} | "
        f"{s['bad2_offset_filtered']:.2f} | {100 * s['recovered']:.0f} % | {s['bad2_offset_oracle']:.2f} | "
        f"{100 * s['recovered_oracle']:.0f} % |"
        for ds, s in summary.items()
    ]
    lines.append(
        f"\nfilter cost, {cost['points']} points on {cost['shape']}, one thread: median "
        f"{cost['filter_ms_median']:.3f} ms, min {cost['filter_ms_min']:.3f} ms "
        f"(copy of the map: {cost['copy_ms_median']:.3f} ms)"
    )
    return "\n".join([head, *lines])


if __name__ == "__main__":
    sys.exit(main())
