r"""``vpp-service eval``: score matcher / guided stereo / VPP on a dataset with ground truth.

Example::

    vpp-service eval --dataset auto --root ../shared/data/middlebury2005_2006_thirdsize \
        --matcher census-sgm --methods baseline,guided,vpp --density 0.01,0.05 \
        --json out.json --markdown out.md

``--dataset synthetic`` needs no ``--root``: it renders ``--limit`` (default 4)
synthetic scenes (:func:`vpp_service.sources.synthetic.make_scene`, seeds 0..N-1).
A comma list in ``--density`` runs a sweep and writes a bad-2 vs density plot
(``--plot``, default ``<json stem>.png`` next to the JSON, or ``eval_sweep.png``).
``--max-disparity`` defaults, per scene, to the smallest multiple of 16 above the
largest ground-truth disparity (at least 16). Progress goes to stderr, the
Markdown summary to stdout.

A LiDAR beside the camera: ``--sensor lidar --sensor-opt pose=kitti`` (or
``pose=[tx,ty,tz]``, the LiDAR origin in the left camera frame in metres, and
optionally ``rotation=[rx,ry,rz]`` in degrees). ``--depth-filter`` chooses the
see-through filter before VPP/guidance: ``auto`` (default: on for LiDAR-like
sensors, i.e. ``lidar`` with a ``pose`` and a dataset's own LiDAR scan), ``see-through``
(always) or ``none``; ``--depth-filter-opt`` sets its window and margins
(``window_w``, ``window_h``, ``margin``, ``min_gap``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from vpp_service.cli.options import key_value

if TYPE_CHECKING:
    from vpp_service.evaluation.runner import Frames
    from vpp_service.vpp import VPPConfig


def _densities(text: str) -> list[float]:
    try:
        values = [float(t) for t in text.split(",") if t.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"--density: expected numbers separated by commas, got {text!r}") from None
    if not values or any(not 0 < v <= 1 for v in values):
        raise argparse.ArgumentTypeError(f"--density: each value must be in (0, 1], got {text!r}")
    return values


def add_parser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> argparse.ArgumentParser:
    """Register the ``eval`` sub-command."""
    p = subparsers.add_parser(
        "eval",
        help="evaluate matcher / guided / VPP against ground truth",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    g = p.add_argument_group("data")
    g.add_argument("--dataset", default="auto", help="reader name, 'auto' (detect) or 'synthetic' (default auto)")
    g.add_argument("--root", type=Path, help="dataset folder (required unless --dataset synthetic)")
    g.add_argument("--scenes", help="comma list of scene names to keep")
    g.add_argument("--limit", type=int, help="evaluate only the first N scenes")
    g.add_argument(
        "--dataset-opt",
        action="append",
        type=key_value,
        default=[],
        metavar="KEY=VALUE",
        help="reader option, e.g. scale=2 (repeatable; VALUE parsed as JSON when possible)",
    )
    g = p.add_argument_group("methods")
    g.add_argument("--matcher", default="census-sgm", help="registered matcher (default census-sgm)")
    g.add_argument(
        "--matcher-opt",
        action="append",
        type=key_value,
        default=[],
        metavar="KEY=VALUE",
        help="matcher option (repeatable)",
    )
    g.add_argument(
        "--methods",
        help="comma list of baseline, guided, vpp (default: all three; baseline,vpp for a matcher without "
        "guided stereo, e.g. sgbm, bm or a network, saying so)",
    )
    g.add_argument("--max-disparity", type=int, help="matcher disparity range (default: per scene from GT)")
    g = p.add_argument_group("sparse points")
    g.add_argument("--sensor", default="uniform", help="uniform | lidar | tof | frame (the dataset's own scan)")
    g.add_argument(
        "--sensor-opt",
        action="append",
        type=key_value,
        default=[],
        metavar="KEY=VALUE",
        help="sensor option (repeatable), e.g. noise_m=0.02",
    )
    g.add_argument(
        "--density",
        type=_densities,
        default=[0.05],
        help="point fraction: fraction of valid GT pixels given a point (uniform sensor); a comma list runs a sweep",
    )
    g.add_argument("--seed", type=int, default=0, help="seed of the points and of the VPP pattern")
    g.add_argument(
        "--depth-filter",
        choices=("auto", "see-through", "none"),
        default="auto",
        help="see-through filter before VPP: auto (default: LiDAR-like sensors), see-through (always), none",
    )
    g.add_argument(
        "--depth-filter-opt",
        action="append",
        type=key_value,
        default=[],
        metavar="KEY=VALUE",
        help="see-through filter option (repeatable): window_w, window_h, margin, min_gap",
    )
    g = p.add_argument_group("VPP")
    g.add_argument(
        "--pattern",
        choices=("random", "histogram"),
        help="pattern values: random bytes, or the value farthest from the search windows' histogram (default random)",
    )
    g.add_argument("--patch", type=int, help="patch side (odd)")
    g.add_argument("--uniform-patch", action="store_true", default=None, help="one value per patch")
    g.add_argument("--alpha", type=float, help="blending weight in [0, 1]")
    g.add_argument("--no-splat", dest="splat", action="store_false", default=None, help="no sub-pixel splatting")
    g.add_argument(
        "--occlusion",
        choices=("fgd", "no", "bkgd", "off"),
        help="occlusion strategy; off runs no detection (default fgd)",
    )
    g.add_argument(
        "--adaptive-patch",
        choices=("distance", "bilateral"),
        help="patch grows with disparity, or a bilateral mask inside it (default none)",
    )
    g = p.add_argument_group("output")
    g.add_argument("--json", type=Path, help="write results + summary as JSON")
    g.add_argument("--markdown", type=Path, help="write the Markdown report")
    g.add_argument("--plot", type=Path, help="bad-2 vs density PNG of a sweep (default next to --json)")
    g.add_argument("--per-scene", action="store_true", help="add per-scene tables to the Markdown report")
    g.add_argument("--quiet", action="store_true", help="no progress on stderr")
    p.set_defaults(func=run)
    return p


def _vpp_config(args: argparse.Namespace) -> VPPConfig:
    """The VPP flags over the matcher's preferred setting (``Matcher.preferred_vpp``) over VPP's defaults."""
    from vpp_service.matchers import MATCHERS
    from vpp_service.vpp import VPPConfig

    opts = {
        k: getattr(args, k)
        for k in ("pattern", "patch", "uniform_patch", "alpha", "splat", "occlusion", "adaptive_patch")
        if getattr(args, k) is not None
    }
    preferred = MATCHERS.get(args.matcher).preferred_vpp(dict(args.matcher_opt))
    return VPPConfig(**{**preferred, **opts})


def _frames(args: argparse.Namespace) -> tuple[Frames, str]:
    if args.dataset == "synthetic":
        from vpp_service.sources.synthetic import make_scene

        n = args.limit or 4
        opts = dict(args.dataset_opt)
        frames = [make_scene(seed=i, **opts) for i in range(n)]
        if args.scenes:
            keep = [s.strip() for s in args.scenes.split(",") if s.strip()]
            frames = [f for f in frames if f.name in keep]
            if not frames:
                raise ValueError(f"--scenes: none of {keep} among the synthetic scenes")
        return frames, "synthetic"
    if args.root is None:
        raise ValueError("--root: required (the dataset folder) unless --dataset synthetic")
    from vpp_service.datasets import open_dataset

    ds = open_dataset(args.dataset, args.root, **dict(args.dataset_opt))
    scenes = [s.strip() for s in args.scenes.split(",") if s.strip()] if args.scenes else None
    ds.select(scenes, args.limit)
    return ds, ds.name


def _default_methods(matcher: str) -> str:
    """Every method the matcher supports: ``guided`` only where it has guidance (one stderr line when skipped)."""
    from vpp_service.matchers import MATCHERS

    if MATCHERS.get(matcher).supports_guidance:
        return "baseline,guided,vpp"
    print(
        f"vpp-service eval: methods baseline,vpp (guided skipped: {matcher!r} has no guided stereo, "
        "it needs a cost volume to modulate, as census-sgm has)",
        file=sys.stderr,
    )
    return "baseline,vpp"


def run(args: argparse.Namespace) -> int:
    """Run the evaluation described by ``args``; returns the exit code."""
    from vpp_service.cli import EXIT_INTERRUPTED
    from vpp_service.evaluation import ProgressBar, markdown_report, plot_sweep, run_evaluation, write_json
    from vpp_service.evaluation.runner import EvaluationInterrupted, _check_methods

    methods = _check_methods(args.methods or _default_methods(args.matcher))
    if args.limit is not None and args.limit < 1:
        raise ValueError(f"--limit: must be >= 1, got {args.limit}")
    vpp_config = _vpp_config(args) if "vpp" in methods else None
    from vpp_service.settings import from_mapping
    from vpp_service.vpp.see_through import DepthFilter

    depth_filter = from_mapping(
        DepthFilter, {"mode": args.depth_filter, **dict(args.depth_filter_opt)}, "--depth-filter-opt"
    )
    frames, dataset_name = _frames(args)
    densities = args.density if args.sensor == "uniform" else None
    if args.sensor != "uniform" and len(args.density) > 1:
        raise ValueError(f"--density: a sweep needs --sensor uniform, got {args.sensor!r}")
    partial: EvaluationInterrupted | None = None
    try:
        rows = run_evaluation(
            frames,
            args.matcher,
            methods,
            densities,
            args.sensor,
            vpp_config=vpp_config,
            seed=args.seed,
            progress=None if args.quiet else ProgressBar(sys.stderr),
            matcher_options=dict(args.matcher_opt),
            sensor_options=dict(args.sensor_opt),
            max_disparity=args.max_disparity,
            dataset_name=dataset_name,
            depth_filter=depth_filter,
        )
    except EvaluationInterrupted as exc:  # Ctrl-C: keep what finished, marked partial
        if not exc.rows:
            print("vpp-service eval: interrupted before the first scene finished: nothing written", file=sys.stderr)
            return EXIT_INTERRUPTED
        partial, rows = exc, exc.rows
    config = {
        "dataset": dataset_name,
        "root": str(args.root) if args.root else None,
        "matcher": args.matcher,
        "matcher_options": dict(args.matcher_opt),
        "methods": methods,
        "sensor": args.sensor,
        "sensor_options": dict(args.sensor_opt),
        "densities": densities,
        "seed": args.seed,
        "max_disparity": args.max_disparity,
        "depth_filter": {"mode": args.depth_filter, **dict(args.depth_filter_opt)},
        "vpp": None if vpp_config is None else {k: getattr(vpp_config, k) for k in vpp_config.__dataclass_fields__},
    }
    title = f"VPP evaluation: {dataset_name}"
    if partial is not None:
        config["partial"] = {"scenes_done": partial.scenes_done, "scenes_total": partial.scenes_total}
        title += f" (PARTIAL: interrupted after {partial.scenes_done} of {partial.scenes_total} scenes)"
    text = markdown_report(rows, per_scene=args.per_scene, title=title)
    if args.json:
        write_json(args.json, rows, config)
    if args.markdown:
        args.markdown.write_text(text)
    if densities is not None and len(densities) > 1:
        plot = args.plot or (args.json.with_suffix(".png") if args.json else Path("eval_sweep.png"))
        plot_sweep(plot, rows)
        print(f"plot: {plot}", file=sys.stderr)
    sys.stdout.write(text)
    if partial is not None:
        written = ", ".join(str(x) for x in (args.json, args.markdown) if x) or "stdout only"
        print(
            f"vpp-service eval: interrupted: {partial.scenes_done} of {partial.scenes_total} scenes finished; "
            f"their results are written, marked partial ({written})",
            file=sys.stderr,
        )
        return EXIT_INTERRUPTED
    return 0
