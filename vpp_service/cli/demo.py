"""``vpp-service demo``: VPP on the scikit-image Middlebury pair, no data needed.

Paints the *Motorcycle* pair shipped with scikit-image using simulated sparse
depth (5 % of ground-truth pixels, the paper's protocol), runs OpenCV SGBM with
and without VPP and prints both against ground truth as the three numbers every
report of the service shows: bad-2 of the pixels that got a disparity, density
(the share of ground-truth pixels that got one) and bad-2 with the holes filled
first (as ``eval`` scores). Saves ``demo.png`` (both disparity maps beside the
ground truth with a colour bar in pixels, and their bad-2 error maps), the
painted pair and ``summary.json``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

if TYPE_CHECKING:
    from vpp_service.frame import StereoFrame


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register the ``demo`` sub-command."""
    p = sub.add_parser(
        "demo",
        help="VPP + SGBM on the built-in Middlebury scene (no data needed)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--out", default="vpp-demo", help="output folder for PNGs and summary.json (default: %(default)s)")
    p.add_argument(
        "--density",
        type=float,
        default=0.05,
        help="fraction of GT pixels sampled as sparse depth (default: %(default)s)",
    )
    p.add_argument("--seed", type=int, default=0, help="seed for sampling and the pattern (default: %(default)s)")
    p.add_argument("--matcher", default="sgbm", help="matcher name (default: %(default)s)")
    p.set_defaults(func=run)


def _scores(disparity: np.ndarray, frame: StereoFrame) -> dict[str, Any]:
    """The three reported numbers (``bad2_answered``, ``density``, ``bad2_filled``) and the filled metrics."""
    from vpp_service.fusion import score

    live = score(disparity, frame)
    return {k: live[k] for k in ("bad2_answered", "density", "bad2_filled")} | {
        "filled": score(disparity, frame, protocol=True)
    }


def run(args: argparse.Namespace) -> int:
    """Run the demo (the ``demo`` sub-command); returns the exit status."""
    from vpp_service.datasets.skimage_scene import motorcycle
    from vpp_service.evaluation.report import plot_comparison
    from vpp_service.fusion import fuse
    from vpp_service.matchers import build_matcher
    from vpp_service.sources.sensors import build_sensor
    from vpp_service.vpp import VPPConfig

    if not 0.0 < args.density <= 1.0:
        raise ValueError(f"--density must be in (0, 1], got {args.density}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    frame = motorcycle().with_(name="Motorcycle (skimage)")
    frame = build_sensor("uniform", {"density": args.density}).simulate(frame, seed=args.seed)
    left, right, gt, sparse = frame.left, frame.right, frame.gt_disparity, frame.sparse_disparity
    assert gt is not None and sparse is not None  # the scene has ground truth, the sensor sets the points
    max_disp = int(np.ceil(np.nanmax(gt) / 16.0) * 16)
    matcher = build_matcher(args.matcher, {"max_disparity": max_disp})
    matcher.warm_up(left, right)  # untimed: a network's engine opens on its first pair, no method's cost

    base = fuse(frame, matcher, None, depth=False)
    fused = fuse(frame, matcher, VPPConfig(), seed=args.seed, depth=False)
    t_base, t_vpp, t_fused = base.timing_ms["match"], fused.timing_ms.get("vpp", 0.0), fused.timing_ms["match"]
    scores = {name: _scores(res.disparity, frame) for name, res in (("baseline", base), ("vpp", fused))}
    n_points = int(np.count_nonzero(np.isfinite(sparse) & (sparse > 0)))
    print(
        f"scene: {frame.name} {left.shape[1]}x{left.shape[0]}, {n_points} sparse points "
        f"({args.density:.1%}), matcher {args.matcher}, max disparity {max_disp}"
    )
    print(f"{'method':<10}{'bad-2 %':>9}{'density %':>11}{'filled bad-2 %':>16}{'filled avg px':>15}{'ms':>8}")
    for name, ms in (("baseline", f"{t_base:>8.1f}"), ("vpp", f"{t_vpp + t_fused:>8.1f}  (VPP {t_vpp:.1f} ms)")):
        s = scores[name]
        print(
            f"{name:<10}{s['bad2_answered']:>9.2f}{s['density']:>11.1f}{s['bad2_filled']:>16.2f}"
            f"{s['filled']['avg']:>15.2f}{ms}"
        )
    print(
        "bad-2: % of the pixels with a disparity that are off by > 2 px; density: % of ground-truth pixels "
        "with a disparity; filled: holes filled before scoring, as eval and docs/results.md score"
    )

    # without a usable point VPP paints nothing: the matcher saw the raw pair
    left_vpp = fused.left_vpp if fused.left_vpp is not None else left
    right_vpp = fused.right_vpp if fused.right_vpp is not None else right
    cv2.imwrite(str(out / "left_vpp.png"), cv2.cvtColor(left_vpp, cv2.COLOR_RGB2BGR))
    cv2.imwrite(str(out / "right_vpp.png"), cv2.cvtColor(right_vpp, cv2.COLOR_RGB2BGR))

    def caption(name: str) -> str:
        s = scores[name]
        return f"bad-2 {s['bad2_answered']:.2f} % | density {s['density']:.1f} % | filled {s['bad2_filled']:.2f} %"

    plot_comparison(
        out / "demo.png",
        left_vpp,
        gt,
        {
            f"{args.matcher} alone": (base.disparity, caption("baseline")),
            f"VPP + {args.matcher}": (fused.disparity, caption("vpp")),
        },
        f"{frame.name}: {args.matcher} with and without VPP ({n_points} sparse points, {args.density:.1%})",
    )
    summary = {
        "scene": frame.name,
        "density": args.density,
        "seed": args.seed,
        "matcher": args.matcher,
        "n_points": n_points,
        "vpp_stats": fused.vpp_stats,
        "baseline": scores["baseline"],
        "vpp": scores["vpp"],
        "ms": {"baseline": t_base, "vpp": t_vpp, "vpp_match": t_fused},
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=float))
    print(f"wrote {out}/demo.png, left_vpp.png, right_vpp.png, summary.json", file=sys.stderr)
    return 0
