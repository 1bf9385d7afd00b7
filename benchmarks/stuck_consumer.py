"""Whether a subscriber that never reads slows the healthy consumers of the zenoh sink's outputs.

The zenoh sink publishes 1000 x 750 float32 disparity maps (3 MB) at ``--rate``
Hz for ``--seconds`` to two client sessions on loopback: a healthy one that
counts what it receives, and, in the second run of each policy, a stuck one
with a one-slot channel nobody reads (once it is full that session stops
reading its link, so TCP back-pressure reaches the publisher). For
``congestion_control`` = ``drop`` and ``block`` the table gives the healthy
consumer's rate with the stuck one present as a share of its rate without it
(target: >= 90 %). Figures are written as JSON to ``--json`` (default
``out/stuck_consumer.json``, ignored by git).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import socket
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def _port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def _conf(listen: list[str], connect: list[str]) -> Any:
    import zenoh

    c = zenoh.Config()
    c.insert_json5("mode", '"peer"')
    c.insert_json5("listen/endpoints", json.dumps(listen))
    c.insert_json5("connect/endpoints", json.dumps(connect))
    c.insert_json5("scouting/multicast/enabled", "false")
    return c


def measure(policy: str, stuck: bool, rate_hz: float, seconds: float) -> dict[str, float]:
    """Healthy consumer's received rate while the sink publishes at ``rate_hz``."""
    import zenoh

    from vpp_service.frame import FusionResult, StereoFrame
    from vpp_service.service.app import zenoh_config
    from vpp_service.service.config import ZenohSection
    from vpp_service.sinks.base import SinkContext, build_sink

    ep = f"tcp/127.0.0.1:{_port()}"
    got: list[float] = []
    svc = zenoh.open(zenoh_config(ZenohSection(listen=[ep])))
    healthy = zenoh.open(_conf([], [ep]))
    blocked = zenoh.open(_conf([], [ep]))
    try:
        healthy.declare_subscriber("vpp/rig0/out/disparity", lambda s: got.append(time.monotonic()))
        # the stuck consumer: a one-slot channel nobody reads; once full, its session stops reading the link
        stuck_sub = (
            blocked.declare_subscriber("vpp/rig0/out/disparity", zenoh.handlers.FifoChannel(1)) if stuck else None
        )
        sink = build_sink(
            "zenoh",
            {"outputs": ["disparity"], "congestion_control": policy, "shm_pool_mb": 0, "queue_size": 2},
            SinkContext(rig="rig0", session=svc),
        )
        sink.open()
        time.sleep(0.5)
        frame = StereoFrame(np.zeros((750, 1000, 3), np.uint8), np.zeros((750, 1000, 3), np.uint8), rig="rig0")
        disp = np.random.default_rng(0).random((750, 1000), dtype=np.float32)
        t0 = time.monotonic()
        n = 0
        while time.monotonic() - t0 < seconds:
            sink.write(FusionResult(frame.with_(seq=n), disp))
            n += 1
            time.sleep(max(0.0, t0 + n / rate_hz - time.monotonic()))
        time.sleep(0.5)
        received = sum(1 for t in got if t <= t0 + seconds + 0.5)
        stats = sink.stats()
        sink.close(2.0)
        del stuck_sub
    finally:
        for session in (blocked, healthy, svc):
            with contextlib.suppress(zenoh.ZError):  # the stuck session cannot close cleanly
                session.close()
    return {"sent": n, "received": received, "rate_hz": received / seconds, "sink_dropped": stats["dropped"]}


def main(argv: list[str] | None = None) -> int:
    """Command line: measure both policies with and without a stuck consumer."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rate", type=float, default=20.0)
    ap.add_argument("--seconds", type=float, default=6.0)
    ap.add_argument("--json", default=str(ROOT / "out" / "stuck_consumer.json"))
    a = ap.parse_args(argv)
    out: dict[str, Any] = {}
    print(f"{'policy':8s} {'alone Hz':>9s} {'stuck Hz':>9s} {'share':>7s} {'sink drops (stuck)':>19s}")
    for policy in ("drop", "block"):
        alone = measure(policy, False, a.rate, a.seconds)
        with_stuck = measure(policy, True, a.rate, a.seconds)
        share = with_stuck["rate_hz"] / alone["rate_hz"] if alone["rate_hz"] else 0.0
        out[policy] = {"alone": alone, "stuck": with_stuck, "share": share}
        print(
            f"{policy:8s} {alone['rate_hz']:>9.1f} {with_stuck['rate_hz']:>9.1f} {100 * share:>6.0f}% "
            f"{with_stuck['sink_dropped']:>19d}"
        )
    path = Path(a.json)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(out, indent=2))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
