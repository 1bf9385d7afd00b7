"""``vpp-service view``: watch a running service's outputs in Rerun, from another machine.

Subscribes to ``<prefix>/<rig>/out/*`` (disparity, depth, the confidence when the
service publishes it, the painted pair and the sparse points; the service's zenoh
sink publishes the last three only while someone subscribes, see its
``on_request`` option) of one rig or of every rig
(``--rig '*'``) and logs them with the Rerun sink's own layout, one recording
per rig: into a spawned viewer (default), a viewer at ``--rerun-connect URL``,
or ``.rrd`` files (``--save PATH``: ``PATH`` itself when one rig was seen; with
``--rig '*'`` and several rigs one file per rig, ``PATH`` with ``-<rig>`` before
the suffix; the files written are named on stderr). Stops on Ctrl-C / SIGTERM, after
``--max-frames`` disparity maps or after ``--duration`` seconds, and prints a
JSON summary (messages received per rig and output, rejected messages, the
Rerun sinks' counters, the files written, and per output its ``gaps``: ``seq``
values skipped between two messages, frames the service dropped or did not publish
or messages lost on the way, e.g. those its zenoh sink's ``congestion_control =
"drop"`` drops to a viewer that does not keep up).

Messages are logged as they arrive: each output comes from the rig's one
service, which publishes it in ``seq`` order, and Zenoh delivers a publisher's
messages in order.

Example (the service on the robot, the viewer on a laptop)::

    vpp-service view --rig rig0 --connect tcp/ROBOT:7447
    vpp-service view --rig '*' --connect tcp/ROBOT:7447 --save watch.rrd --duration 60
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import queue
import signal
import sys
import threading
import time
from collections import Counter, defaultdict
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING

from vpp_service.errors import StartupError
from vpp_service.queueing import QueueWorker

if TYPE_CHECKING:
    import zenoh

    from vpp_service.sinks.rerun import RerunSink
    from vpp_service.sinks.rerun_log import RerunParts

log = logging.getLogger(__name__)

#: The outputs the viewer shows.
VIEWED = ("disparity", "depth", "confidence", "left_vpp", "right_vpp", "sparse")


def add_parser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register the ``view`` sub-command."""
    p = subparsers.add_parser(
        "view",
        help="show a running service's outputs in Rerun (another machine, one rig or '*')",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--rig", default="*", help="rig to watch; '*' = every rig (default)")
    p.add_argument("--prefix", default="vpp", help="Zenoh key prefix of the service (default vpp)")
    p.add_argument(
        "--connect",
        action="append",
        default=[],
        metavar="ENDPOINT",
        help="Zenoh endpoint of the service (repeatable; default tcp/127.0.0.1:7447)",
    )
    p.add_argument("--multicast-scouting", action="store_true", help="also find the service by multicast")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--save", metavar="PATH", help="write .rrd file(s) instead of spawning a viewer")
    where.add_argument("--rerun-connect", metavar="URL", help="stream to a running viewer (rerun+http://H:P/proxy)")
    p.add_argument("--max-frames", type=int, default=0, help="stop after N disparity maps (0 = no limit)")
    p.add_argument("--duration", type=float, default=0.0, help="stop after S seconds (0 = no limit)")
    p.set_defaults(func=main)


def rig_path(path: str, rig: str, wildcard: bool) -> str:
    """The ``.rrd`` of ``rig``: ``path`` itself for one rig, ``<stem>-<rig><suffix>`` with ``--rig '*'``."""
    if not wildcard:
        return path
    p = Path(path)
    return str(p.with_name(f"{p.stem}-{rig}{p.suffix or '.rrd'}"))


def decode_part(name: str, payload: bytes, rig: str) -> RerunParts:
    """One ``out/<name>`` message as :class:`~vpp_service.sinks.rerun_log.RerunParts` (only its fields set).

    Raises
    ------
    vpp_service.transport.wire.WireError
        A malformed message, or one whose ``rig`` is not the rig of its key.
    """
    from vpp_service.sinks.rerun_log import RerunParts
    from vpp_service.transport import wire

    if name in ("disparity", "depth", "confidence"):
        m = wire.decode_output(payload)
        parts = RerunParts(m.rig, m.seq, m.stamp_ns, timing_ms=m.timing_ms)
        if name == "disparity":
            parts.disparity = m.data
        elif name == "confidence":
            parts.confidence = m.data
        else:  # metric depth and its calibration: the 3-D view
            parts.depth, parts.calib = m.data, m.calib
    elif name == "sparse":
        pts = wire.decode_output_points(payload)
        parts = RerunParts(pts.rig, pts.seq, pts.stamp_ns, sparse=pts.points)
    else:
        seq, img = wire.decode_output_image(payload)  # validates the header too
        msg = wire.unpack(payload)
        stamp = msg.get("stamp_ns")
        parts = RerunParts(str(msg.get("rig")), seq, stamp if isinstance(stamp, int) else 0)
        if name == "left_vpp":
            parts.left = img
        else:
            parts.right = img
    if parts.rig != rig:
        raise wire.WireError(f"rig: message says {parts.rig!r} on the key of rig {rig!r}")
    return parts


class Viewer:
    """Per-rig Rerun sinks fed from received output messages.

    Parameters
    ----------
    options : dict
        ``rerun`` sink options shared by every rig (``path`` is made per rig).
    wildcard : bool
        Watching ``'*'``: one ``.rrd`` per rig.
    """

    def __init__(self, options: dict[str, object], wildcard: bool) -> None:
        self.options = options
        self.wildcard = wildcard
        self.last_seq: dict[tuple[str, str], int] = {}  # per rig and output
        self.gaps: dict[str, Counter[str]] = defaultdict(Counter)
        self.sinks: dict[str, RerunSink] = {}
        self.workers: dict[str, QueueWorker[RerunParts]] = {}  # each rig's queue and logging thread
        self.received: dict[str, Counter[str]] = defaultdict(Counter)
        self.rejected = 0

    def sink(self, rig: str) -> RerunSink:
        """The rig's sink, built and opened on its first message."""
        from vpp_service.sinks.base import SinkContext, build_sink
        from vpp_service.sinks.rerun import RerunSink

        if rig not in self.sinks:
            opts = dict(self.options)
            if opts.get("mode") == "save":
                opts["path"] = rig_path(str(opts["path"]), rig, self.wildcard)
            sink = build_sink("rerun", opts, SinkContext(rig=rig))
            assert isinstance(sink, RerunSink)
            sink.open()

            def submit(parts: RerunParts, s: RerunSink = sink) -> None:
                s.submit(parts)  # looked up per call on the instance (tests patch it)

            worker: QueueWorker[RerunParts] = QueueWorker(
                submit,
                size=sink.queue_spec().size or 64,
                name=f"view-{rig}",
                on_start=sink.start,
                on_exit=sink.finish,
            )
            worker.start()
            self.sinks[rig], self.workers[rig] = sink, worker
            log.info("view: watching rig %s", rig)
        return self.sinks[rig]

    def handle(self, key: str, payload: bytes) -> str | None:
        """Log one ``<prefix>/<rig>/out/<name>`` message; returns its output name (None when rejected)."""
        from vpp_service.sinks.rerun_log import ENTITY_RE
        from vpp_service.transport.wire import WireError

        *_, rig, _, name = key.split("/")
        if name not in VIEWED or not ENTITY_RE.match(rig):
            self.rejected += 1
            return None
        try:
            parts = decode_part(name, payload, rig)
        except WireError as exc:
            self.rejected += 1
            log.warning("view: %s rejected: %s", key, exc)
            return None
        self.received[rig][name] += 1
        last = self.last_seq.get((rig, name))
        if last is not None and parts.seq > last + 1:
            self.gaps[rig][name] += parts.seq - last - 1  # a seq at or below the last: the service restarted
        self.last_seq[rig, name] = parts.seq
        self.sink(rig)
        self.workers[rig].put(parts)  # logged on the rig's thread; a full queue drops the oldest (counted)
        return name

    def close(self, timeout: float = 5.0) -> dict[str, object]:
        """Close every sink; the summary of what was received and logged."""
        for rig, sink in self.sinks.items():
            self.workers[rig].close(timeout)
            sink.close(timeout)
        saved = [str(s.options.path) for s in self.sinks.values() if s.options.mode == "save"]
        if self.wildcard and len(saved) == 1:  # '*' and one rig seen: the file asked for, not PATH-<rig>
            (only,) = self.sinks.values()
            saved = [_rename(Path(saved[0]), Path(str(self.options["path"])), only.options.max_files)]
        return {
            "rigs": {
                rig: {
                    "received": dict(self.received[rig]),
                    "gaps": {name: self.gaps[rig][name] for name in self.received[rig]},
                    "rerun": sink.stats(),
                    "queue_dropped": self.workers[rig].dropped + self.workers[rig].discarded,
                }
                for rig, sink in self.sinks.items()
            },
            "rejected": self.rejected,
            "saved": saved,
        }


def _rename(written: Path, asked: Path, max_files: int) -> str:
    """Move the recording ``written`` (and its rotated parts) to ``asked``; the path that now holds it."""
    from vpp_service.sinks.rerun import rotated_paths

    try:
        for src, dst in zip(rotated_paths(written, max_files), rotated_paths(asked, max_files), strict=True):
            if src.exists():
                src.replace(dst)
            elif dst.exists():
                dst.unlink()  # an older recording's part would read as a part of this one
    except OSError as exc:
        log.warning("view: could not rename %s to %s: %s", written, asked, exc)
        return str(written)
    return str(asked)


def main(args: argparse.Namespace) -> int:
    """Subscribe, log into Rerun until stopped, print the JSON summary."""
    from vpp_service.cli import EXIT_FAILURE
    from vpp_service.service.app import zenoh_session
    from vpp_service.service.config import ZenohSection, default_endpoint
    from vpp_service.transport.wire import topic

    if args.max_frames < 0 or args.duration < 0:
        raise ValueError("--max-frames and --duration must be >= 0")
    if args.rig != "*":
        topic(args.prefix, args.rig, "out")  # validates the names (ValueError: exit 2)
    options = _rerun_options(args)
    viewer = Viewer(options, wildcard=args.rig == "*")
    inbox: queue.Queue[tuple[str, bytes]] = queue.Queue(maxsize=256)
    lost = [0]

    def on_sample(sample: zenoh.Sample) -> None:
        try:
            inbox.put_nowait((str(sample.key_expr), sample.payload.to_bytes()))
        except queue.Full:
            lost[0] += 1

    stop = threading.Event()

    def on_signal(signum: int, _frame: FrameType | None) -> None:
        stop.set()

    old = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    zsec = ZenohSection(
        mode="peer",
        listen=[],
        connect=args.connect or [default_endpoint()],
        multicast_scouting=args.multicast_scouting,
    )
    frames, t_end = 0, (time.monotonic() + args.duration) if args.duration else float("inf")
    try:
        with zenoh_session(zsec) as session:
            if not _linked(session, stop, LINK_WAIT_S):
                print(f"vpp-service view: could not connect to {', '.join(zsec.connect)}", file=sys.stderr)
                return EXIT_FAILURE
            sub = session.declare_subscriber(f"{args.prefix}/{args.rig}/out/*", on_sample)
            where = ", ".join(zsec.connect)
            print(f"view: watching {args.prefix}/{args.rig}/out/* via {where}", file=sys.stderr, flush=True)
            while not stop.is_set() and time.monotonic() < t_end:
                try:
                    key, payload = inbox.get(timeout=0.1)
                except queue.Empty:
                    continue
                if viewer.handle(key, payload) == "disparity":
                    frames += 1
                    if args.max_frames and frames >= args.max_frames:
                        break
            sub.undeclare()
    finally:
        for s, h in old.items():
            signal.signal(s, h)
        summary = viewer.close()
    summary["lost"] = lost[0]
    print(json.dumps(summary))
    saved = summary["saved"]
    if isinstance(saved, list) and saved:
        print(f"view: wrote {', '.join(map(str, saved))}", file=sys.stderr)
    failed = [rig for rig, sink in viewer.sinks.items() if sink.stats()["errors"] and not sink.stats()["written"]]
    if failed:
        print(
            f"vpp-service view: the Rerun output ({options['mode']}) could not start for {', '.join(failed)}; "
            "see the log above",
            file=sys.stderr,
        )
        return EXIT_FAILURE
    return 0


def _rerun_options(args: argparse.Namespace) -> dict[str, object]:
    """The Rerun sink options of ``--save`` / ``--rerun-connect`` / a spawned viewer (checked up front).

    Raises
    ------
    FileNotFoundError
        ``--save`` into a folder that does not exist.
    StartupError
        A viewer to spawn on a Linux machine without a display.
    """
    options: dict[str, object] = {"max_hz": 0, "queue_size": 64}
    if args.save:
        if not Path(args.save).expanduser().parent.is_dir():
            raise FileNotFoundError(f"--save: folder {str(Path(args.save).parent)!r} does not exist")
        options.update(mode="save", path=args.save)
    elif args.rerun_connect:
        options.update(mode="connect", url=args.rerun_connect)
    else:
        if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
            raise StartupError(
                "cannot spawn a Rerun viewer: no display here (DISPLAY and WAYLAND_DISPLAY are unset); "
                "use --save PATH or --rerun-connect URL"
            )
        options.update(mode="spawn")
    return options


#: How long ``view`` waits for its session to reach a connect endpoint before it gives up.
LINK_WAIT_S = 3.0


def _linked(session: zenoh.Session, stop: threading.Event, seconds: float) -> bool:
    """Wait up to ``seconds`` for ``session`` to reach a router or peer; True once it has."""
    from vpp_service.service.app import has_link

    deadline = time.monotonic() + seconds
    while not has_link(session):
        if stop.is_set() or time.monotonic() >= deadline:
            return False
        time.sleep(0.05)
    return True
