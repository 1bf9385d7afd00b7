"""vpp-service publish: play a dataset or the simulator onto Zenoh like a camera rig.

Frames (with sparse depth and, as an extension, ground truth) are sent as wire
format v1 on <prefix>/<rig>/in/frame or, with --separate-topics, on
in/left, in/right and in/depth. It connects to the same default endpoint that
vpp-service run listens on, waits for a matching subscriber (a service started
with --source zenoh) and exits 1 with a message when none appears, unless
--send-anyway. Publishing uses reliable CongestionControl.BLOCK, so frames are
never silently dropped on the way; after the last frame it waits (--confirm-timeout)
for the service's @status reply, which travels behind the frames, before closing the
session (closing drops what is still queued).
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import signal
import sys
import threading
import time
from collections.abc import Iterable
from typing import TYPE_CHECKING

from vpp_service.cli.help import HelpFormatter, plain

log = logging.getLogger(__name__)

if TYPE_CHECKING:  # imported where they are used: the sub-command modules load no kernel at import time
    import zenoh

    from vpp_service.frame import StereoFrame
    from vpp_service.service.config import ZenohSection
    from vpp_service.sources.base import Source
    from vpp_service.transport.shm import ShmPutter


def add_parser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register the ``publish`` sub-command."""
    from vpp_service.service.config import ENDPOINT_ENV, default_endpoint

    p = subparsers.add_parser(
        "publish",
        help="publish frames onto Zenoh as a camera rig would",
        description=plain(__doc__),
        formatter_class=HelpFormatter,
    )
    p.add_argument("--dataset", help="dataset name or 'auto' (default: the simulator; 'auto' when --root is given)")
    p.add_argument("--root", help="dataset folder (implies --dataset auto)")
    p.add_argument(
        "--recording", metavar="DIR", help="replay a folder of .msgpack frames (the record sink's output) instead"
    )
    p.add_argument("--rosbag", metavar="PATH", help="replay a rosbag2 bag (.db3/.mcap) onto rmw_zenoh topics instead")
    p.add_argument("--rosbag-rate", type=float, default=1.0, help="--rosbag: recorded-timing multiplier (0 = fastest)")
    p.add_argument("--ros-domain", type=int, default=0, help="--rosbag: ROS 2 domain id")
    p.add_argument("--scene", default="motorcycle", choices=["motorcycle", "synthetic"], help="simulator scene")
    p.add_argument("--scale", type=float, default=1.0, help="resize factor in (0, 1]")
    p.add_argument("--sensor", default="uniform", help="sensor simulator (uniform, lidar, tof, none)")
    p.add_argument("--density", type=float, default=0.05, help="point fraction of the uniform sensor (its density)")
    p.add_argument(
        "--nominal-f",
        type=float,
        default=1000.0,
        metavar="PX",
        help="focal length sent with frames whose dataset has no calibration (Middlebury 2001-2006), pixels; "
        "the same nominal value the simulator's sensors use",
    )
    p.add_argument(
        "--nominal-baseline",
        type=float,
        default=0.1,
        metavar="M",
        help="baseline sent with frames whose dataset has no calibration, metres",
    )
    p.add_argument(
        "--calib",
        nargs=2,
        metavar=("LEFT", "RIGHT"),
        help="the rig's camera_info YAMLs: the frames are raw (a service with [rectify] rectifies them) and go "
        "without calib and without simulated depth (drawn from rectified ground truth, it is not in the raw frame)",
    )
    p.add_argument("--rate", type=float, default=10.0, help="frames per second (0 = as fast as possible)")
    p.add_argument("--count", type=int, default=0, help="frames to send (0 = until interrupted / end)")
    p.add_argument("--loop", action="store_true", help="loop over the dataset")
    p.add_argument("--rig", default="rig0", help="rig name: frames go to <prefix>/<rig>/in/...")
    p.add_argument("--prefix", default="vpp", help="Zenoh key prefix")
    p.add_argument(
        "--connect",
        action="append",
        default=[],
        metavar="ENDPOINT",
        help=f"connect endpoint (repeatable; default {default_endpoint()}, or ${ENDPOINT_ENV}, unless --listen)",
    )
    p.add_argument("--listen", action="append", default=[], metavar="ENDPOINT", help="listen endpoint (repeatable)")
    p.add_argument("--multicast-scouting", action="store_true", help="enable multicast discovery")
    p.add_argument("--enc", default="raw", choices=["raw", "png", "jpeg"], help="image encoding")
    p.add_argument(
        "--depth-kind",
        default="auto",
        choices=["auto", "points", "disparity_points", "map"],
        help="how sparse depth is sent: 3-D points, (u, v, disparity) points, or a sparse map",
    )
    p.add_argument("--no-depth", action="store_true", help="send frames without sparse depth")
    p.add_argument("--no-gt", action="store_true", help="do not attach ground truth")
    p.add_argument("--separate-topics", action="store_true", help="publish in/left, in/right, in/depth")
    p.add_argument(
        "--wait-subscriber",
        type=float,
        default=5.0,
        metavar="S",
        help="wait up to S seconds for a matching subscriber before sending (0 = don't wait)",
    )
    p.add_argument(
        "--send-anyway",
        action="store_true",
        help="send even when no subscriber matched within --wait-subscriber (else exit 1)",
    )
    p.add_argument(
        "--confirm-timeout",
        type=float,
        default=60.0,
        metavar="S",
        help="after the last frame, wait up to S seconds for the service's @status reply, which comes only "
        "after every frame sent before it has reached the service (0 = exit at once)",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the simulated depth sensor")
    p.add_argument(
        "--shm-pool-mb",
        type=int,
        default=64,
        metavar="MB",
        help="publish large messages from a shared-memory pool of this size (0 = plain puts)",
    )
    p.set_defaults(func=main)


def _has_subscriber(publisher: zenoh.Publisher) -> bool:
    """True when a subscriber matches ``publisher``'s key."""
    import zenoh

    status: object = publisher.matching_status  # zenoh's stub says bool; at run time it is a MatchingStatus
    return status.matching if isinstance(status, zenoh.MatchingStatus) else bool(status)


def _wait_for_subscribers(pubs: Iterable[zenoh.Publisher], seconds: float, stop: threading.Event) -> bool:
    """Wait up to ``seconds`` (or until ``stop``) for a subscriber on every publisher; True when all have one."""
    deadline = time.monotonic() + seconds
    while not stop.is_set():
        if all(_has_subscriber(pub) for pub in pubs):
            return True
        if time.monotonic() >= deadline:
            return False
        time.sleep(0.02)
    return False


def _confirm_delivery(session: zenoh.Session, prefix: str, rig: str, seconds: float) -> bool:
    """Wait until the frames already put have reached the rig's service; True when one confirmed it.

    Closing the session drops what its queues still hold (a service using the ``block``
    input policy pushes back, so a backlog builds up). A query for
    ``<prefix>/<rig>/@status`` travels behind the frames on the same link at the same
    priority, and the service reads its link in order, so its reply means every frame
    sent before the query has been handed to its subscriber.
    """
    from vpp_service.transport import wire

    t0 = time.monotonic()
    replies = session.get(wire.topic(prefix, rig, "@status"), timeout=seconds)
    if any(reply.ok is not None for reply in replies):
        return True
    waited = time.monotonic() - t0
    if waited < 0.9 * seconds:  # the query ended early: nothing that serves the rig's @status was reachable
        log.warning(
            "no service of rig %r is reachable any more (its @status query ended after %.1f s with no reply): "
            "frames still queued may be lost",
            rig,
            waited,
        )
    else:
        log.warning(
            "no @status reply from a service of rig %r within %g s: frames still queued may be lost",
            rig,
            seconds,
        )
    return False


def _check_args(args: argparse.Namespace) -> None:
    """Reject bad numeric flags before anything starts."""
    if not 0 < args.scale <= 1:
        raise ValueError(f"--scale: must be in (0, 1], got {args.scale}")
    if args.rate < 0 or args.count < 0:
        raise ValueError("--rate and --count must be >= 0")
    if not args.confirm_timeout >= 0:
        raise ValueError(f"--confirm-timeout: must be >= 0, got {args.confirm_timeout}")
    for flag, value in (("--nominal-f", args.nominal_f), ("--nominal-baseline", args.nominal_baseline)):
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{flag}: must be a finite number > 0, got {value}")
    if getattr(args, "calib", None):
        from vpp_service.rectify import check_pair, read_camera_info

        try:
            check_pair(*(read_camera_info(p) for p in args.calib))
        except ValueError as exc:
            raise ValueError(f"--calib: {exc}") from None


def with_calibration(frame: StereoFrame, f: float, baseline: float) -> StereoFrame:
    """``frame`` unchanged when it has a calibration, else with a nominal one (a rectified frame needs one).

    The principal point is the image centre and ``doffs`` 0; sparse depth sent as 3-D points is
    converted with the same values on both ends, so the disparities the service uses are the dataset's.
    """
    from vpp_service.frame import Calibration

    if frame.calib is not None:
        return frame
    h, w = frame.left.shape[:2]
    return frame.with_(calib=Calibration(f=f, baseline=baseline, cx=(w - 1) / 2.0, cy=(h - 1) / 2.0))


def _send(frame: StereoFrame, args: argparse.Namespace, pubs: dict[str, zenoh.Publisher], putter: ShmPutter) -> None:
    """Stamp ``frame``, strip what the flags say, publish it on ``pubs`` (one topic per part, or ``frame``)."""
    from vpp_service.transport import wire

    if getattr(args, "calib", None):  # a raw frame: the service's [rectify] has the calibration
        frame = frame.with_(calib=None, sparse_disparity=None, sensor_depth=None, stamp_ns=time.time_ns())
    else:
        frame = with_calibration(frame, args.nominal_f, args.nominal_baseline).with_(stamp_ns=time.time_ns())
    if args.no_depth:
        frame = frame.with_(sparse_disparity=None, sensor_depth=None)
    if args.no_gt:
        frame = frame.with_(gt_disparity=None)
    if not args.separate_topics:
        putter.put(pubs["frame"], wire.encode_frame(frame, args.enc, args.depth_kind))
        return
    for part, pub in pubs.items():
        payload = wire.encode_part(frame, part, args.enc, args.depth_kind)
        if payload is not None:
            putter.put(pub, payload)


def _source(args: argparse.Namespace) -> Source:
    from vpp_service.sources.base import SourceContext, build_source

    ctx = SourceContext(rig=args.rig, prefix=args.prefix)
    sensor_opts = {"density": args.density} if args.sensor == "uniform" else {}
    if args.recording:
        if args.dataset or args.root:
            raise ValueError("--recording and --dataset/--root: give one of them")
        return build_source(
            "files",
            {"root": args.recording, "format": "msgpack", "rate_hz": 0.0, "loop": args.loop, "count": args.count},
            ctx,
        )
    if args.root and not args.dataset:
        args.dataset = "auto"  # a folder to play: find its format
    if args.dataset:
        if not args.root:
            raise ValueError("--root: required with --dataset")
        opts = {
            "root": args.root,
            "dataset": args.dataset,
            "rate_hz": 0.0,
            "loop": args.loop,
            "count": args.count,
            "scale": args.scale,
            "sensor": args.sensor,
            "sensor_options": sensor_opts,
            "seed": args.seed,
        }
        return build_source("files", opts, ctx)
    opts = {
        "scene": args.scene,
        "scale": args.scale,
        "sensor": args.sensor,
        "sensor_options": sensor_opts,
        "rate_hz": 0.0,
        "count": args.count,
        "seed": args.seed,
    }
    return build_source("sim", opts, ctx)


def main(args: argparse.Namespace) -> int:
    """Publish until ``--count``, the end of the dataset, or SIGINT/SIGTERM."""
    if getattr(args, "rosbag", None):
        from vpp_service.cli.publish_rosbag import play

        return play(args)
    from vpp_service.service.config import ZenohSection, default_endpoint
    from vpp_service.transport.shm import ShmPutter

    _check_args(args)
    putter = ShmPutter(args.shm_pool_mb)  # validates the pool size before anything starts
    connect = list(args.connect) or ([] if args.listen else [default_endpoint()])
    zsec = ZenohSection(
        mode="peer", listen=list(args.listen), connect=connect, multicast_scouting=args.multicast_scouting
    )
    src = _source(args)
    src.open()
    stop = threading.Event()
    try:
        return _publish(args, src, stop, zsec, putter)
    finally:  # whatever happened: no producing thread is left running when the interpreter exits
        stop.set()
        src.stop(2.0)


def _publish(
    args: argparse.Namespace, src: Source, stop: threading.Event, zsec: ZenohSection, putter: ShmPutter
) -> int:
    """Send ``src``'s frames until it ends, ``--count`` or a signal; print the report (the caller stops ``src``)."""
    import queue as _queue

    import zenoh

    from vpp_service.cli import EXIT_INTERRUPTED
    from vpp_service.service.app import has_link, zenoh_session
    from vpp_service.sources.base import Pacer
    from vpp_service.transport import wire

    frames: _queue.Queue[StereoFrame] = _queue.Queue(maxsize=2)
    for s in (signal.SIGINT, signal.SIGTERM):
        signal.signal(s, lambda *_: stop.set())

    def emit(frame: StereoFrame) -> bool:
        while not stop.is_set():
            try:
                frames.put(frame, timeout=0.1)
                return True
            except _queue.Full:
                continue
        return False

    parts = ["left", "right", "depth"] if args.separate_topics else ["frame"]
    sent = 0
    with zenoh_session(zsec) as session:
        pubs = {
            p: session.declare_publisher(
                wire.topic(args.prefix, args.rig, f"in/{p}"), congestion_control=zenoh.CongestionControl.BLOCK
            )
            for p in parts
        }
        if args.wait_subscriber > 0 and not _wait_for_subscribers(pubs.values(), args.wait_subscriber, stop):
            if stop.is_set():  # interrupted while waiting
                return EXIT_INTERRUPTED
            if zsec.connect and not args.send_anyway and not has_link(session):
                print(
                    f"vpp-service publish: could not connect to {', '.join(zsec.connect)} (nothing replies there); "
                    "start `vpp-service run --source zenoh` there, or pass --connect",
                    file=sys.stderr,
                )
                return 1
            if not args.send_anyway:
                where = ", ".join(list(zsec.connect) + list(zsec.listen))
                keys = ", ".join(str(pub.key_expr) for pub in pubs.values())
                print(
                    f"vpp-service publish: no subscriber on {keys} within {args.wait_subscriber:g} s "
                    f"(via {where}); start `vpp-service run --source zenoh` there, or pass --send-anyway",
                    file=sys.stderr,
                )
                return 1
            log.warning("no subscriber on %s; sending anyway", [str(p.key_expr) for p in pubs.values()])
        src.start(emit)
        pacer = Pacer(args.rate)
        t0 = time.monotonic()
        while not stop.is_set():
            try:
                frame = frames.get(timeout=0.1)
            except _queue.Empty:
                if src.finished.is_set() and frames.empty():
                    break
                continue
            if pacer.wait(src) and stop.is_set():
                break
            _send(frame, args, pubs, putter)
            sent += 1
        src.stop(2.0)
        elapsed = time.monotonic() - t0
        confirmed = None
        if sent and args.confirm_timeout > 0 and not stop.is_set():
            confirmed = _confirm_delivery(session, args.prefix, args.rig, args.confirm_timeout)
        for pub in pubs.values():
            pub.undeclare()
    report = {"sent": sent, "seconds": round(elapsed, 3), "confirmed": confirmed, "shm": putter.stats()}
    print(json.dumps(report), file=sys.stdout)
    return 0
