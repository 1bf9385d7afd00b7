"""``vpp-service demo``: VPP on the scikit-image Middlebury pair, no data needed.

Paints the *Motorcycle* pair shipped with scikit-image using simulated sparse
depth (5 % of ground-truth pixels, the paper's protocol), runs OpenCV SGBM with
and without VPP and prints both against ground truth as the three numbers every
report of the service shows: bad-2 of the pixels that got a disparity, density
(the share of ground-truth pixels that got one) and bad-2 with the holes filled
first (as ``eval`` scores). Saves ``demo.png`` (both disparity maps beside the
ground truth with a colour bar in pixels, and their bad-2 error maps), the
painted pair and ``summary.json`` in ``--out``. Like ``run``, it refuses to
write over a previous demo's files unless ``--overwrite``; a demo that fails
leaves no folder it created behind.
"""

from __future__ import annotations

import argparse
import json
import shutil
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
        help="point fraction: fraction of GT pixels sampled as sparse depth (default: %(default)s)",
    )
    p.add_argument("--seed", type=int, default=0, help="seed for sampling and the pattern (default: %(default)s)")
    p.add_argument("--matcher", default="sgbm", help="matcher name (default: %(default)s)")
    p.add_argument(
        "--overwrite", action="store_true", help="replace a previous demo's files in --out (without it: refuse)"
    )
    p.set_defaults(func=run)


#: The files a demo writes into ``--out``.
OUTPUTS = ("demo.png", "left_vpp.png", "right_vpp.png", "summary.json")


def _check_out(out: Path, overwrite: bool) -> None:
    """``out`` must be a folder (or not exist yet) without a previous demo's files unless ``overwrite``.

    Raises
    ------
    NotADirectoryError
        ``out`` is a file.
    StartupError
        ``out`` holds a previous demo's files and ``overwrite`` is false.
    """
    from vpp_service.errors import StartupError

    if out.exists() and not out.is_dir():
        raise NotADirectoryError(f"--out: {str(out)!r} is not a folder")
    previous = [name for name in OUTPUTS if (out / name).exists()]
    if previous and not overwrite:
        raise StartupError(
            f"--out: {str(out)!r} holds a previous demo's files ({', '.join(previous)}); "
            "pass --overwrite to replace them, or --out DIR for a new folder"
        )


def _make_dir(out: Path) -> Path | None:
    """Create ``out`` (with parents); the topmost folder this created, None when ``out`` existed."""
    top = None
    for folder in [out, *out.parents]:
        if folder.exists():
            break
        top = folder
    out.mkdir(parents=True, exist_ok=True)
    return top


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
    _check_out(out, args.overwrite)

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

    def caption(name: str) -> str:
        s = scores[name]
        return f"bad-2 {s['bad2_answered']:.2f} % | density {s['density']:.1f} % | filled {s['bad2_filled']:.2f} %"

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
    created = _make_dir(out)
    try:
        for name, img in (("left_vpp.png", left_vpp), ("right_vpp.png", right_vpp)):
            if not cv2.imwrite(str(out / name), cv2.cvtColor(img, cv2.COLOR_RGB2BGR)):
                raise OSError(f"--out: could not write {out / name}")
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
        (out / "summary.json").write_text(json.dumps(summary, indent=2, default=float))
    except BaseException:
        if created is not None:  # a folder this demo made: leave nothing behind
            shutil.rmtree(created, ignore_errors=True)
        else:  # the user's folder: take out this demo's partial files, nothing else
            for name in OUTPUTS:
                (out / name).unlink(missing_ok=True)
        raise
    print(f"wrote {out}/demo.png, left_vpp.png, right_vpp.png, summary.json", file=sys.stderr)
    return 0
