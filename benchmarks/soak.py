"""Soak: hostile messages interleaved with valid frames against the running service, on loopback.

Starts the service in this process (``run_service``: zenoh source on a free
127.0.0.1 port, VPP + SGBM, ``files``, ``record`` and ``zenoh`` sinks into a
temporary folder), and from a second Zenoh session sends, before every valid
frame, a batch of hostile messages cycling through every kind of
``tests/helpers/hostile.py`` (malformed msgpack, caps, lying image headers,
forged rigs, ...). Valid frames carry hostile ``stamp_ns`` values too. Each
valid frame is awaited before the next batch, so every valid frame must come
through. During the flood the zenoh source's ``max_message_mb`` is
``--flood-mb`` (2 MiB), so the large kinds are built to that size and the
run takes a minute; then the largest kinds are sent once more at the
session's full 64 MiB (rejected by length in the callback) while the resident
size is sampled, and every kind is decoded in-process at the full 64 MiB caps.

Checks and figures (printed as a table, written as JSON to ``--json``,
default ``out/soak.json``, a path git ignores):

* the service never crashes and replies to ``@status`` to the end;
* 100 % of valid frames processed; every hostile message counted (``rejected``
  plus anything a ring dropped);
* no file written outside the sinks' folders;
* per kind, the time and peak resident growth of ``decode_frame`` rejecting a
  message built to the default 64 MiB caps;
* peak resident growth of this process (service and camera together) while a
  64 MiB message goes through Zenoh, and the resident size after the run
  (after the service trims freed memory);
* latency p99 (from receive time: hostile stamps must not move it).

One more mode attacks the ROS 2 path (``--mode``):

``ros2``
    The service with the ``ros2`` source and sink; a robot (``tests/helpers/ros2_robot.py``)
    sends, before every genuine stereo set, hostile parts carrying the set's own stamp
    (a ``8UC4`` image, a step that does not match the data, a camera_info with a zero ``P``,
    a cloud without ``x y z``) and a burst of junk samples (no rmw_zenoh attachment, or over
    ``max_message_mb``) into 4-deep rings. Figures: genuine sets delivered, rejections by cause,
    and the source's ledger (every received sample in exactly one count).

Usage::

    python benchmarks/soak.py                      # 10,000 hostile messages, 100 valid frames
    python benchmarks/soak.py --hostile 500 --valid 20 --no-full-size   # a quick run
    python benchmarks/soak.py --mode ros2 --valid 300 --junk 96       # ROS 2 input under attack
"""

from __future__ import annotations

import argparse
import json
import socket
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT / "tests") not in sys.path:
    sys.path.insert(0, str(ROOT / "tests"))  # the hostile-message generator is shared with the tests

from helpers import hostile  # noqa: E402
from vpp_service.transport import wire  # noqa: E402

RIG = "rig0"


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def _rss_mb() -> float:
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * 4096 / 2**20


class RssSampler:
    """Samples this process's resident size every ``period_s`` in a thread; ``peak`` since :meth:`reset`."""

    def __init__(self, period_s: float = 0.005) -> None:
        self.period_s = period_s
        self.peak = _rss_mb()
        self._lock = threading.Lock()  # a sample read before a reset must not land after it
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.wait(self.period_s):
            with self._lock:
                self.peak = max(self.peak, _rss_mb())

    def reset(self) -> float:
        """Start a new peak from the current size; returns it."""
        with self._lock:
            self.peak = _rss_mb()
            return self.peak

    def stop(self) -> None:
        """Stop sampling."""
        self._stop.set()
        self._thread.join(1.0)


def decode_cost(cap: int) -> dict[str, dict[str, Any]]:
    """Per kind: wall time and resident growth of ``decode_frame`` on a message sized to ``cap``, and its outcome."""
    limits = wire.WireLimits(max_message_bytes=cap)
    sampler = RssSampler(0.001)
    out: dict[str, dict[str, Any]] = {}
    for kind in hostile.KINDS:
        msg = hostile.hostile_message(kind, 1, cap)
        base = sampler.reset()
        t0 = time.perf_counter()
        try:
            rig = wire.decode_frame(msg, limits).rig
            outcome = f"decoded, rig {rig!r} (rejected by the pipeline)"
        except wire.WireError as exc:
            outcome = str(exc)[:80]
        ms = (time.perf_counter() - t0) * 1e3
        time.sleep(0.005)
        out[kind] = {"bytes": len(msg), "ms": ms, "peak_growth_mb": sampler.peak - base, "outcome": outcome}
        del msg
    sampler.stop()
    return out


def _config(port: int, folder: Path, ring: int, max_message_mb: float) -> dict[str, Any]:
    return {
        "service": {"rig": RIG, "out": str(folder / "run"), "summary": False, "reject_log_period_s": 5.0},
        "zenoh": {"mode": "peer", "listen": [f"tcp/127.0.0.1:{port}"], "connect": []},
        "source": {"type": "zenoh", "ring_size": ring, "max_message_mb": max_message_mb},
        "vpp": {"enabled": True},
        "matcher": {"name": "sgbm", "max_disparity": 16},
        "queues": {"input_size": 2, "input_policy": "block", "output_size": 4, "output_policy": "block"},
        "sinks": [
            {"type": "zenoh", "outputs": ["disparity"]},
            {"type": "files", "dir": str(folder / "files"), "create_dir": True},
            {"type": "record", "dir": str(folder / "rec"), "create_dir": True, "enc": "raw"},
        ],
    }


def run(  # noqa: PLR0915 - one scenario, step by step
    n_hostile: int = 10_000, n_valid: int = 100, full_size: bool = True, flood_mb: float = 2.0, timeout_s: float = 30.0
) -> dict[str, Any]:
    """Run the soak; return its figures (see the module docstring)."""
    import zenoh

    from vpp_service.service.allocator import trim_freed_memory
    from vpp_service.service.app import run_service
    from vpp_service.service.config import validate_config

    kinds = list(hostile.KINDS)
    per_batch = max(1, -(-n_hostile // max(1, n_valid)))
    base = Path(tempfile.mkdtemp(prefix="vpp-soak-"))
    folder = base / "a" / "b"  # "../../x" from a sink folder lands in base/a: watched below
    port = _free_port()
    cfg = validate_config(_config(port, folder, ring=per_batch + 8, max_message_mb=flood_mb))
    stop = threading.Event()
    result: dict[str, Any] = {}
    crash: list[BaseException] = []

    def service() -> None:
        try:
            result["summary"] = run_service(cfg, stop, stream=None)
        except BaseException as exc:  # noqa: BLE001 - a crash is what the soak reports
            crash.append(exc)

    sampler = RssSampler()
    thread = threading.Thread(target=service, name="soak-service", daemon=True)
    thread.start()
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("connect/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    status_key = wire.topic("vpp", RIG, "@status")
    figures: dict[str, Any] = {"hostile_kinds": len(kinds), "per_batch": per_batch}
    with zenoh.open(conf) as cam:

        def status() -> dict[str, Any] | None:
            for reply in cam.get(status_key, timeout=3.0):
                if reply.ok is not None:
                    st: dict[str, Any] = json.loads(reply.ok.payload.to_string())
                    return st
            return None

        deadline = time.monotonic() + timeout_s
        while status() is None and time.monotonic() < deadline:
            time.sleep(0.1)
        pub = cam.declare_publisher(
            wire.topic("vpp", RIG, "in/frame"), congestion_control=zenoh.CongestionControl.BLOCK
        )
        time.sleep(0.5)
        flood_cap = int(flood_mb * 2**20)
        sent_hostile, sent_valid, processed, stalls = 0, 0, 0, 0
        t_start = time.monotonic()
        stamps = (1, 0, (1 << 63) - 1, time.time_ns() - 3_600_000_000_000)  # far past, zero, far future, an hour ago
        for i in range(n_valid):
            for _ in range(min(per_batch, n_hostile - sent_hostile)):
                kind = kinds[sent_hostile % len(kinds)]
                pub.put(hostile.hostile_message(kind, sent_hostile, flood_cap))
                sent_hostile += 1
            pub.put(hostile.valid_message(RIG, i, stamps[i % len(stamps)], h=48, w=96))
            sent_valid += 1
            deadline = time.monotonic() + timeout_s
            while time.monotonic() < deadline:
                st = status()
                if st is not None and st["counters"]["processed"] >= sent_valid:
                    processed = st["counters"]["processed"]
                    break
                time.sleep(0.02)
            else:
                stalls += 1
        figures["flood_s"] = time.monotonic() - t_start
        while sent_hostile < n_hostile:  # the rest, if n_valid does not divide n_hostile
            pub.put(hostile.hostile_message(kinds[sent_hostile % len(kinds)], sent_hostile, flood_cap))
            sent_hostile += 1
        time.sleep(1.5)  # the service trims memory at most once a second after rejects
        figures["rss_after_flood_mb"] = _rss_mb()

        if full_size:
            cap = wire.DEFAULT_LIMITS.max_message_bytes
            big = {
                k: hostile.hostile_message(k, 0, cap) for k in ("oversize", "nested_empty_maps", "unknown_key_nested")
            }
            big["jpeg_marker_flood"] = hostile.hostile_message("jpeg_marker_flood", 0, cap)
            growth: dict[str, float] = {}
            for kind, msg in big.items():
                time.sleep(1.5)
                n_before = (status() or {"counters": {"received": 0}})["counters"]["received"]
                rss0 = sampler.reset()
                pub.put(msg)
                deadline = time.monotonic() + timeout_s
                while time.monotonic() < deadline:
                    st = status()
                    if st is not None and st["counters"]["received"] > n_before:
                        break
                    time.sleep(0.02)
                time.sleep(0.5)
                growth[kind] = sampler.peak - rss0
                sent_hostile += 1
            del big
            trim_freed_memory()  # the publisher's copies (this process plays the camera too)
            time.sleep(2.5)
            figures["zenoh_64mib_peak_growth_mb"] = growth
        st = status()
        figures["answering_at_end"] = st is not None
    stop.set()
    thread.join(30.0)
    figures["rss_end_mb"] = _rss_mb()
    sampler.stop()
    summary = result.get("summary")
    c = summary["counters"] if summary else {}
    src = summary["source"] if summary else {}
    lat = summary["timing_ms"].get("latency", {}) if summary else {}
    sink_dirs = {folder / "files", folder / "rec", folder / "run"}
    expected = {base / "a", folder} | sink_dirs
    escaped = sorted(str(p) for p in base.rglob("*") if p not in expected and p.parent not in sink_dirs)
    figures.update(
        {
            "crashes": len(crash) + (0 if thread.is_alive() is False else 1),
            "sent_valid": sent_valid,
            "sent_hostile": sent_hostile,
            "processed": c.get("processed", processed),
            "valid_processed_pct": 100.0 * c.get("processed", 0) / max(1, sent_valid),
            "rejected": c.get("rejected"),
            "ring_dropped": src.get("ring_dropped"),
            "received": c.get("received"),
            "hostile_counted_pct": 100.0 * (c.get("rejected", 0) + src.get("ring_dropped", 0)) / max(1, sent_hostile),
            "stalls": stalls,
            "latency_p99_ms": lat.get("p99"),
            "files_outside_sinks": escaped + [p for p in ("/tmp/vpp-hostile-abs",) if Path(p).exists()],
            "files_written": sum(1 for _ in (folder / "files").glob("*")),
            "recorded": sum(1 for _ in (folder / "rec").glob("*.msgpack")),
        }
    )
    return figures


def _hostile_parts(rig: Any, stamp: int) -> list[tuple[str, object]]:
    """Well-formed CDR with bad content and the genuine set's ``stamp``: one of each refused kind."""
    import numpy as np

    from helpers.ros2_robot import camera_info_from_p, cloud_msg, image_msg

    h, w = rig.left.shape[:2]
    step = image_msg(rig.left, stamp, "l")
    step.step = w * 3 + 7  # step x height no longer matches the data
    cloud = cloud_msg(rig.cloud, stamp, "l")
    cloud.fields = cloud.fields[:1]  # x only: no y, z
    return [
        ("left/image_rect", image_msg(np.zeros((h, w, 4), np.uint8), stamp, "l", encoding="8UC4")),
        ("right/image_rect", step),
        ("left/camera_info", camera_info_from_p(stamp, "l", (w, h), np.zeros((3, 4)))),
        ("points", cloud),
    ]


def run_ros2(n_sets: int = 300, junk: int = 96, timeout_s: float = 30.0) -> dict[str, Any]:
    """ROS 2 input under attack (see the module docstring); returns the figures."""
    import numpy as np
    import zenoh

    from helpers.ros2_robot import Robot, StereoRig
    from vpp_service.service.app import run_service
    from vpp_service.service.config import validate_config

    port = _free_port()
    base = Path(tempfile.mkdtemp(prefix="vpp-soak-ros2-"))
    cfg = validate_config(
        {
            "service": {"rig": RIG, "out": str(base / "run"), "summary": False, "reject_log_period_s": 5.0},
            "zenoh": {"mode": "peer", "listen": [f"tcp/127.0.0.1:{port}"], "connect": []},
            "source": {"type": "ros2", "ring_size": 4, "max_message_mb": 0.05, "depth_wait_ms": 2000.0},
            "vpp": {"enabled": True},
            "matcher": {"name": "sgbm", "max_disparity": 16},
            "queues": {"input_size": 2, "input_policy": "block", "output_size": 4, "output_policy": "block"},
            "sinks": [{"type": "ros2", "outputs": ["disparity"]}],
        }
    )
    stop = threading.Event()
    result: dict[str, Any] = {}
    thread = threading.Thread(target=lambda: result.update(run_service(cfg, stop, stream=None)), daemon=True)
    thread.start()
    rng = np.random.default_rng(0)
    img = rng.integers(0, 256, (48, 96, 3), dtype=np.uint8)
    cloud = np.array([[0.0, 0.0, 2.0], [0.1, 0.05, 2.5]], np.float32)
    rig = StereoRig(img, np.roll(img, -4, axis=1), 100.0, 0.1, 47.5, 47.5, 23.5, cloud)
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("connect/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    figures: dict[str, Any] = {"mode": "ros2", "junk_per_set": junk, "hostile_parts_per_set": 4}
    stalls = 0
    with zenoh.open(conf) as session:
        robot = Robot(session)
        sub = robot.subscribe_disparity()
        if not robot.wait_for_subscribers(["left/image_rect", "right/image_rect", "points"], timeout=timeout_s):
            raise RuntimeError("the service's subscribers never appeared")
        got = 0
        t0 = time.monotonic()
        for k in range(n_sets):
            stamp = 1_000_000 + k * 1000
            for name, msg in _hostile_parts(rig, stamp):
                robot.put(name, msg)
            for j in range(junk):
                name = ("left/image_rect", "right/image_rect", "left/camera_info", "points")[j % 4]
                if j % 2:  # no attachment: not an rmw_zenoh publisher
                    robot.pubs[name].put(b"\x00\x01\x00\x00junk")
                else:  # over max_message_mb
                    robot.pubs[name].put(b"\x00\x01\x00\x00" + bytes(64 * 1024), attachment=bytes(33))
            robot.publish(rig, stamp)
            deadline = time.monotonic() + timeout_s
            while got <= k and time.monotonic() < deadline:
                if sub.try_recv() is not None:
                    got += 1
                else:
                    time.sleep(0.002)
            if got <= k:
                stalls += 1
        figures["seconds"] = time.monotonic() - t0
        robot.close()
    stop.set()
    thread.join(30.0)
    summary = result.get("summary", result)
    src = summary.get("source", {})
    ledger = src.get("messages", {})
    ends = sum(v for k, v in ledger.items() if k != "received")
    figures.update(
        {
            "sent_sets": n_sets,
            "delivered": got,
            "delivered_pct": 100.0 * got / max(1, n_sets),
            "processed": summary.get("counters", {}).get("processed"),
            "stalls": stalls,
            "rejected_by": src.get("rejected_by"),
            "dropped": summary.get("dropped"),
            "messages": ledger,
            "messages_accounted": ledger.get("received") == ends,
        }
    )
    return figures


def main(argv: list[str] | None = None) -> int:
    """Command line: run the soak, print the figures, write them as JSON."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hostile", type=int, default=10_000, help="hostile messages in all")
    ap.add_argument("--valid", type=int, default=100, help="valid frames (one after every batch)")
    ap.add_argument("--flood-mb", type=float, default=2.0, help="size the flood kinds are built to during the soak")
    ap.add_argument("--no-full-size", action="store_true", help="skip the phase of 64 MiB hostile messages")
    ap.add_argument("--json", default=str(ROOT / "out" / "soak.json"), help="where the figures go (git ignores out/)")
    ap.add_argument("--mode", choices=("zenoh", "ros2"), default="zenoh", help="which path to attack")
    ap.add_argument("--junk", type=int, default=96, help="ros2 mode: junk samples before every genuine set")
    a = ap.parse_args(argv)
    if a.mode != "zenoh":
        figures = run_ros2(a.valid, a.junk)
        for key, value in figures.items():
            print(f"{key:28s} {value}")
        path = Path(a.json)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(figures, indent=2, default=str))
        print(f"wrote {path}")
        counted = figures.get("messages_accounted", figures.get("every_loss_counted"))
        return 0 if figures["delivered_pct"] >= 99.0 and counted else 1
    cost = decode_cost(wire.DEFAULT_LIMITS.max_message_bytes)
    print(f"{'kind':24s} {'bytes':>10s} {'reject ms':>10s} {'peak MB':>8s}  outcome")
    for kind, row in cost.items():
        print(f"{kind:24s} {row['bytes']:>10d} {row['ms']:>10.2f} {row['peak_growth_mb']:>8.1f}  {row['outcome']}")
    figures = run(a.hostile, a.valid, not a.no_full_size, a.flood_mb)
    figures["decode_cost"] = cost
    figures["max_reject_ms"] = max(row["ms"] for row in cost.values())
    figures["max_decode_peak_growth_mb"] = max(row["peak_growth_mb"] for row in cost.values())
    for key, value in figures.items():
        if key != "decode_cost":
            print(f"{key:28s} {value}")
    path = Path(a.json)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(figures, indent=2, default=str))
    print(f"wrote {path}")
    ok = figures["crashes"] == 0 and figures["valid_processed_pct"] == 100.0 and not figures["files_outside_sinks"]
    return 0 if ok and figures["hostile_counted_pct"] == 100.0 else 1


if __name__ == "__main__":
    sys.exit(main())
