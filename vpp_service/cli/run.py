"""vpp-service run: run the streaming service.

With no arguments it runs the embedded default (:data:`vpp_service.service.config.DEFAULT_CONFIG`):
the simulated Motorcycle rig with a uniform 5 % sensor, VPP + SGBM, publishing on
a local Zenoh peer (``tcp/127.0.0.1:7447``, the endpoint publish and status use too;
multicast scouting off) and saving ``vpp-run/vpp.rrd``. With ``--source zenoh`` it
takes frames from ``vpp-service publish`` or a camera instead, losslessly by default
(``--input-policy block``; a live camera wants ``latest``). It prints one line when
it has started (endpoint, topics, the matcher and the engine, device and precision that run it, sinks)
Stops on SIGINT/SIGTERM (clean, bounded shutdown, exit 0) or after ``--max-frames``
(frames processed or rejected); exits 1 when the source died on an error (a runtime
failure), 2 when a frame arrives that the disparity range cannot fit (``--max-disparity``
not below its width: a configuration error; ``--check`` finds it when the source
knows its frame size, as the sim source does).
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import signal
import sys
import threading
from collections.abc import Mapping
from types import FrameType
from typing import TYPE_CHECKING, Any

from vpp_service.cli.help import HelpFormatter, plain
from vpp_service.cli.options import key_value

if TYPE_CHECKING:
    from vpp_service.service.config import ServiceConfig


def add_parser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register the ``run`` sub-command."""
    p = subparsers.add_parser(
        "run",
        help="run the streaming fusion service",
        description=plain(__doc__),
        formatter_class=HelpFormatter,
    )
    p.add_argument("--config", help="TOML config file (default: the embedded default)")
    p.add_argument("--rig", help="rig name (service.rig; default: the config's, rig0)")
    p.add_argument(
        "--source",
        help="source type: sim, files, zenoh, ros2, rosbag2 (options from the config; default: the config's, sim)",
    )
    p.add_argument("--sink", action="append", help="sink type (repeatable; replaces the config's sinks)")
    p.add_argument("--matcher", help="matcher name: sgbm, bm, census-sgm, psmnet, onnx (default: the config's, sgbm)")
    p.add_argument(
        "--matcher-opt",
        action="append",
        type=key_value,
        default=[],
        metavar="KEY=VALUE",
        help="matcher option (repeatable; VALUE parsed as JSON when possible), e.g. model=psmnet.onnx",
    )
    p.add_argument(
        "--max-disparity",
        metavar="D",
        help='matcher disparity range: "auto" (per frame from the calibration and [matcher.auto_range] '
        "min_depth_m, else the frame's sparse points plus a margin, rounded up to 16) or an integer "
        "(default: the config's, auto)",
    )
    p.add_argument(
        "--input-policy",
        choices=["latest", "block"],
        help="input queue when full: drop the oldest (live camera) or wait (lossless replay); "
        "default: the config's, and block with --source zenoh",
    )
    p.add_argument(
        "--zenoh-listen",
        action="append",
        metavar="ENDPOINT",
        help="listen endpoint (repeatable; default tcp/127.0.0.1:7447, the one publish and status use, "
        "or $VPP_SERVICE_ENDPOINT)",
    )
    p.add_argument("--zenoh-connect", action="append", metavar="ENDPOINT", help="connect endpoint (repeatable)")
    viewer = p.add_mutually_exclusive_group()
    viewer.add_argument("--rerun-save", metavar="PATH", help="save a Rerun .rrd here (adds/replaces the rerun sink)")
    viewer.add_argument(
        "--rerun-connect",
        metavar="URL",
        nargs="?",
        const="rerun+http://127.0.0.1:9876/proxy",
        help="stream to a running Rerun viewer (default URL rerun+http://127.0.0.1:9876/proxy)",
    )
    viewer.add_argument(
        "--rerun-serve",
        metavar="PORT",
        nargs="?",
        type=int,
        const=9876,
        help="host a Rerun gRPC server on 127.0.0.1:PORT (default 9876) for viewers that connect later",
    )
    viewer.add_argument("--rerun-spawn", action="store_true", help="spawn a local Rerun viewer and stream to it")
    viewer.add_argument("--headless", action="store_true", help="no Rerun output at all (drops the rerun sink)")
    p.add_argument("--rosbag", metavar="PATH", help="play a rosbag2 bag (.db3/.mcap) as the source (type rosbag2)")
    p.add_argument("--ros-namespace", metavar="NS", help="ROS 2 namespace of the ros2 source and sinks (e.g. /stereo)")
    p.add_argument("--ros-domain", type=int, metavar="ID", help="ROS 2 domain id of the ros2 source and sinks")
    p.add_argument(
        "--max-frames",
        type=int,
        help="stop after N frames processed or rejected (default: the config's, 0 = run until stopped)",
    )
    p.add_argument("--out", help="output folder for summary.json and the default .rrd (default: the config's, vpp-run)")
    p.add_argument("--no-summary", action="store_true", help="no live summary line on stderr")
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace a previous run's outputs in --out (summary.json, .rrd, recorded frames); without it or "
        "--resume, run refuses to start over them (service.overwrite)",
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="start over a previous run's outputs in --out by keeping them: summary.json -> summary.1.json, the "
        ".rrd rotated, frame folders continued (service.resume; the default for --source zenoh/ros2; the systemd "
        "unit passes it)",
    )
    p.add_argument(
        "--check",
        action="store_true",
        help="validate the configuration and the paths it names, print it as JSON, exit (2 on an error)",
    )
    p.set_defaults(func=main)


#: Options of a sink named by ``--sink`` that the config does not list.
_SINK_DEFAULTS: dict[str, dict[str, object]] = {
    "rerun": {"mode": "save", "path": "{out}/vpp.rrd"},
    "files": {"dir": "{out}/frames", "create_dir": True},
    "record": {"dir": "{out}/recording", "create_dir": True},
    "rosbag2": {"path": "{out}/bag"},
}


def _sinks_from_flag(names: list[str], configured: list[object]) -> list[dict[str, Any]]:
    """The sinks of ``--sink NAME ...``: the config's entry for a type it lists, else that type's defaults."""
    old = {s.get("type"): s for s in configured if isinstance(s, dict)}
    return [old[t] if t in old else {"type": t, **_SINK_DEFAULTS.get(t, {})} for t in names]


def _int_or_text(value: str) -> int | str:
    """``value`` as an int when it is one (the config check names anything else)."""
    try:
        return int(value)
    except ValueError:
        return value


def overrides_from_args(data: dict[str, Any], args: argparse.Namespace) -> dict[str, Any]:
    """Apply the CLI flags to a raw config mapping (returns a new mapping)."""
    d = copy.deepcopy(data)
    _service_overrides(d.setdefault("service", {}), args)
    if args.source and d.get("source", {}).get("type") != args.source:
        d["source"] = {"type": args.source}
        if args.source == "zenoh" and "input_policy" not in d.get("queues", {}):
            d.setdefault("queues", {})["input_policy"] = "block"  # a replay into the service loses nothing
    if args.input_policy:
        d.setdefault("queues", {})["input_policy"] = args.input_policy
    if args.matcher and d.get("matcher", {}).get("name") != args.matcher:
        d["matcher"] = {"name": args.matcher}
    for key, value in getattr(args, "matcher_opt", None) or []:
        d.setdefault("matcher", {"name": "sgbm"})[key] = value
    max_disparity = getattr(args, "max_disparity", None)
    if max_disparity is not None:
        m = d.setdefault("matcher", {"name": "sgbm"})
        m["max_disparity"] = _int_or_text(max_disparity)
        if m["max_disparity"] != "auto":
            m.pop("auto_range", None)
    zen = d.setdefault("zenoh", {})
    if args.zenoh_listen:
        zen["listen"] = list(args.zenoh_listen)
    if args.zenoh_connect:
        zen["connect"] = list(args.zenoh_connect)
    if args.sink is not None:
        d["sinks"] = _sinks_from_flag(args.sink, d.get("sinks", []))
    rerun = _rerun_flag(args)
    if rerun is not None:
        is_rerun = [isinstance(s, dict) and s.get("type") == "rerun" for s in d.get("sinks", [])]
        old: dict[str, Any] = next((s for s, r in zip(d.get("sinks", []), is_rerun, strict=True) if r), {})
        sinks = [s for s, r in zip(d.get("sinks", []), is_rerun, strict=True) if not r]
        if rerun:  # keep the configured sink's other options (max_hz, ranges, ...), replace where it goes
            kept = {k: v for k, v in old.items() if k not in ("mode", "path", "url", "grpc_port")}
            sinks.append({**kept, "type": "rerun", **rerun})
        d["sinks"] = sinks
    _ros_overrides(d, args)
    return d


def _service_overrides(svc: dict[str, Any], args: argparse.Namespace) -> None:
    """Apply the ``[service]`` flags (--rig, --max-frames, --out, --no-summary, --overwrite, --resume)."""
    if args.rig:
        svc["rig"] = args.rig
    if args.max_frames is not None:
        svc["max_frames"] = args.max_frames
    if args.out:
        svc["out"] = args.out
    if args.no_summary:
        svc["summary"] = False
    if getattr(args, "overwrite", False):
        svc["overwrite"] = True
    if getattr(args, "resume", False):
        svc["resume"] = True


def _rerun_flag(args: argparse.Namespace) -> dict[str, object] | None:
    """The rerun sink's output asked for by ``--rerun-*`` / ``--headless`` ({} = none); None = no such flag."""
    if getattr(args, "headless", False):
        return {}
    if getattr(args, "rerun_save", None):
        return {"mode": "save", "path": args.rerun_save}
    if getattr(args, "rerun_connect", None):
        return {"mode": "connect", "url": args.rerun_connect}
    if getattr(args, "rerun_serve", None) is not None:
        return {"mode": "serve", "grpc_port": args.rerun_serve}
    if getattr(args, "rerun_spawn", False):
        return {"mode": "spawn"}
    return None


def _ros_overrides(d: dict[str, Any], args: argparse.Namespace) -> None:
    """``--rosbag`` (the rosbag2 source), ``--ros-namespace`` / ``--ros-domain`` (ros2 source and sinks)."""
    bag = getattr(args, "rosbag", None)
    if bag:
        src = d.get("source", {})
        d["source"] = {**src, "path": bag} if src.get("type") == "rosbag2" else {"type": "rosbag2", "path": bag}
    pairs = (("namespace", getattr(args, "ros_namespace", None)), ("domain_id", getattr(args, "ros_domain", None)))
    ros = {k: v for k, v in pairs if v is not None}
    for section in [d.get("source"), *d.get("sinks", [])]:
        if ros and isinstance(section, dict) and section.get("type") == "ros2":
            section.update(ros)
        elif ros.get("namespace") and isinstance(section, dict) and section.get("type") == "rosbag2":
            section["namespace"] = ros["namespace"]


def main(args: argparse.Namespace) -> int:
    """Validate the whole configuration, then run until done or signalled."""
    from vpp_service.cli import EXIT_STARTUP
    from vpp_service.errors import StartupError
    from vpp_service.service.app import run_service
    from vpp_service.service.config import DEFAULT_CONFIG, check_paths, previous_outputs, read_toml, validate_config
    from vpp_service.service.resume import resume_outputs, resumes

    data = overrides_from_args(read_toml(args.config) if args.config else copy.deepcopy(DEFAULT_CONFIG), args)
    cfg = validate_config(data)
    check_paths(cfg, servers_required=args.check)  # run: a Triton server down at start is waited for
    if args.check:
        print(json.dumps(cfg.to_dict(), indent=2))
        return 0
    previous = [] if cfg.service.overwrite else previous_outputs(cfg)
    if previous and resumes(cfg):
        try:
            moved = resume_outputs(cfg)
        except OSError as exc:
            raise StartupError(f"service.out: cannot keep the previous run's outputs: {exc}") from None
        print(
            f"vpp-service run: resuming in {cfg.service.out} ({'; '.join(moved) or 'frames continue'})", file=sys.stderr
        )
    elif previous:
        raise StartupError(
            f"service.out: {cfg.service.out!r} holds a previous run's outputs ({', '.join(previous)}); "
            "pass --overwrite to replace them, --resume to keep them (summary.json rotated), "
            "or --out DIR for a new run folder"
        )
    stop = threading.Event()

    def on_signal(signum: int, _frame: FrameType | None) -> None:
        stop.set()

    old = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        status = run_service(cfg, stop, sys.stderr, banner=lambda matcher: startup_line(cfg, matcher))
    finally:
        for s, h in old.items():
            signal.signal(s, h)
    by_cause = status["source"].get("rejected_by")
    rejected_by = {str(k): int(v) for k, v in by_cause.items()} if isinstance(by_cause, dict) else None
    print(closing_line(cfg, status["counters"], status["dropped"], rejected_by), file=sys.stderr)
    print(
        json.dumps(
            {"counters": status["counters"], "out": cfg.service.out, "shutdown_s": round(status["shutdown_s"], 3)}
        )
    )
    if status["config_error"] is not None:  # the configuration cannot process the frames: restarting won't help
        print(f"vpp-service run: stopped: {status['config_error']}", file=sys.stderr)
        return EXIT_STARTUP
    if status["source_error"] is not None:  # a dead source is a runtime failure: exit 1 so systemd restarts it
        print(f"vpp-service run: the source failed: {status['source_error']}", file=sys.stderr)
        return 1
    if status["unfinished_sinks"]:
        print(
            f"vpp-service run: {', '.join(status['unfinished_sinks'])} could not finish within "
            f"{cfg.service.shutdown_timeout_s:g} s: their outputs may be incomplete",
            file=sys.stderr,
        )
        # a sink library stuck at interpreter exit (Rerun's atexit flush on a full disk) must not hang the
        # process: leave now, with the streams flushed and a failure status
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(1)
    return 0


def _sink_text(spec_name: str, raw: dict[str, Any]) -> str:
    """``name`` plus the file or folder it writes, when it names one."""
    where = raw.get("path") if raw.get("mode", "save") == "save" else raw.get("mode")
    where = where or raw.get("dir")
    return f"{spec_name} ({where})" if where else spec_name


def matcher_text(name: str, runtime: Mapping[str, object] | None) -> str:
    """``"sgbm (opencv cpu int16, 2 threads)"``: the matcher and what runs it (name alone when unknown)."""
    if not runtime:
        return name
    threads = runtime.get("threads")
    what = " ".join(str(runtime[k]) for k in ("engine", "device", "precision") if k in runtime)
    return f"{runtime.get('name', name)} ({what}" + (f", {threads} threads)" if threads is not None else ")")


def startup_line(cfg: ServiceConfig, matcher: Mapping[str, object] | None = None) -> str:
    """The line ``run`` prints once started: rig, Zenoh endpoints, input, matcher and what runs it, outputs, sinks.

    ``matcher`` is :attr:`~vpp_service.service.pipeline.Pipeline.matcher_runtime` (engine, device, precision).
    """
    from vpp_service.transport.wire import topic

    s, z = cfg.service, cfg.zenoh
    if z.enabled:
        ends = [f"listen {e}" for e in z.listen] + [f"connect {e}" for e in z.connect]
        zenoh_s = f"zenoh {z.mode} {', '.join(ends) or 'no endpoints'}"
    else:
        zenoh_s = "zenoh off"
    src = f"in {topic(s.prefix, s.rig, 'in/*')}" if cfg.source.name == "zenoh" else f"source {cfg.source.name}"
    sinks = ", ".join(_sink_text(sp.name, sp.raw) for sp in cfg.sinks) or "none"
    outputs = f" | out {topic(s.prefix, s.rig, 'out/*')}" if any(sp.name == "zenoh" for sp in cfg.sinks) else ""
    status = topic(s.prefix, s.rig, "@status")
    return (
        f"vpp-service run: rig {s.rig} | {zenoh_s} | {src} | matcher {matcher_text(cfg.matcher.name, matcher)}"
        f"{outputs} | sinks {sinks} | status {status} | stop with Ctrl-C"
    )


def plural(n: int, noun: str) -> str:
    """``"1 frame"``, ``"3 frames"``."""
    return f"{n} {noun}" if n == 1 else f"{n} {noun}s"


def closing_line(
    cfg: ServiceConfig,
    counters: dict[str, int],
    dropped: Mapping[str, int] | None = None,
    rejected_by: Mapping[str, int] | None = None,
) -> str:
    """The line ``run`` prints when it stops: frames processed, any frames lost or input refused (by cause), files."""
    from pathlib import Path

    files = [str(Path(cfg.service.out) / "summary.json")]
    files += [str(sp.raw["path"]) for sp in cfg.sinks if sp.name == "rerun" and sp.raw.get("mode", "save") == "save"]
    files += [str(sp.raw["dir"]) for sp in cfg.sinks if "dir" in sp.raw]
    missing = [f for f in files if not Path(f).exists()]  # never claim a file that is not there
    files = [f for f in files if f not in missing]
    lost = ""
    if counters.get("dropped", 0):
        causes = ", ".join(f"{k} {v}" for k, v in sorted((dropped or {}).items()) if v)
        lost = f"; dropped {plural(counters['dropped'], 'frame')}" + (f" ({causes})" if causes else "")
    rejected = ""
    if counters.get("rejected", 0):
        causes = ", ".join(f"{k} {v}" for k, v in sorted((rejected_by or {}).items()) if v)
        rejected = f"; rejected {counters['rejected']}" + (f" ({causes})" if causes else "")
    processed = plural(counters.get("processed", 0), "frame")
    wrote = f"; wrote {', '.join(files)}" if files else ""
    not_written = f"; NOT written: {', '.join(missing)}" if missing else ""
    return f"vpp-service run: stopped after {processed}{lost}{rejected}{wrote}{not_written}"
