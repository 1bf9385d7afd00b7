"""Overload run: a camera publishing at 3x what the service can process, with both input policies.

For each policy (``latest``, ``block``) the service runs as its own process
(``python -m vpp_service run``, Zenoh source on a free 127.0.0.1 port, multicast
scouting off); this process is the camera: it publishes synthetic frames on
``vpp/<rig>/in/frame`` reliably with ``CongestionControl.BLOCK`` at ``--factor``
times the measured processing rate for ``--seconds``, then waits for the
service to drain and reads its ``@status`` and ``summary.json``.

Per policy it reports frames sent, processed and lost (sent - processed), the
service's own ``dropped`` count and its causes (every loss must be counted:
``latest`` drops are expected, ``block`` must lose none and instead slow the
camera down: see the achieved publish rate), latency p50/p99 and the service's
RSS (after warm-up, peak, end, growth). Prints a table and writes JSON (by
default to the system's temporary folder: nothing under the repository).

    python benchmarks/overload.py --seconds 120          # the issue's 2-minute run
    python benchmarks/overload.py --seconds 10 --json /tmp/overload.json
    python benchmarks/overload.py --junk-only --seconds 20   # valid frames at 10 Hz under a junk flood, both policies
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Mapping, Sequence
from pathlib import Path

from _harness import write_report

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import zenoh  # noqa: E402 - after the repository is on sys.path

from vpp_service.sources.base import SourceContext, build_source  # noqa: E402
from vpp_service.transport import wire  # noqa: E402

RIG = "ovl"


def _port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def _toml_value(v: object) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, Mapping):
        return "{" + ", ".join(f"{k} = {_toml_value(x)}" for k, x in v.items()) + "}"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return json.dumps(v)


def _toml(cfg: Mapping[str, object]) -> str:
    top = "".join(f"{k} = {_toml_value(v)}\n" for k, v in cfg.items() if not isinstance(v, Mapping))
    return top + "".join(
        f"[{k}]\n" + "".join(f"{kk} = {_toml_value(vv)}\n" for kk, vv in t.items())
        for k, t in cfg.items()
        if isinstance(t, Mapping)
    )


def _frames(a: argparse.Namespace) -> list[bytes]:
    src = build_source(
        "sim",
        {"scene": "synthetic", "scene_options": {"height": a.height, "width": a.width, "max_disparity": 32}},
        SourceContext(rig=RIG),
    )
    src.open()
    return [wire.encode_frame(src.frame(i)) for i in range(8)]


def _rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def _status(session: zenoh.Session) -> dict[str, object] | None:
    for reply in session.get(f"vpp/{RIG}/@status", timeout=3.0):
        if reply.ok is not None:
            st: dict[str, object] = json.loads(reply.ok.payload.to_string())
            return st
    return None


def _run(  # noqa: PLR0915 - one scenario, step by step
    a: argparse.Namespace,
    policy: str,
    payloads: list[bytes],
    *,
    rate_hz: float,
    tmp: Path,
    seconds: float,
    junk: list[bytes] | None = None,
) -> dict[str, object]:
    """One service process under ``policy``, fed at ``rate_hz`` (0 = as fast as it takes) for ``seconds``.

    With ``junk``, a second session floods the same key with those messages as fast as it can meanwhile.
    """
    port = _port()
    name = policy + ("-junk" if junk else "")
    out = tmp / f"out-{name}"
    cfg: dict[str, object] = {
        "service": {"rig": RIG, "out": str(out), "summary": False, "summary_period_s": 1.0},
        "zenoh": {"mode": "peer", "listen": [f"tcp/127.0.0.1:{port}"], "connect": []},
        "source": {"type": "zenoh", "ring_size": 4},
        "matcher": {"name": a.matcher, "max_disparity": 64},
        "queues": {"input_size": 2, "input_policy": policy, "output_size": 4, "output_policy": "latest"},
        "sinks": [{"type": "zenoh", "outputs": ["disparity"]}],
    }
    path = tmp / f"{name}.toml"
    path.write_text(_toml(cfg))
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    log = (tmp / f"{name}.log").open("wb")
    proc = subprocess.Popen(
        [sys.executable, "-m", "vpp_service", "run", "--config", str(path)], cwd=REPO, env=env, stderr=log, stdout=log
    )
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("connect/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    rss: list[float] = []
    flood_stop = threading.Event()
    junk_sent = [0]
    try:
        time.sleep(1.0)
        with zenoh.open(conf) as cam:
            deadline = time.monotonic() + 60
            while _status(cam) is None:
                if time.monotonic() > deadline or proc.poll() is not None:
                    raise RuntimeError(f"the service did not come up (see {tmp / (policy + '.log')})")
                time.sleep(0.3)
            results = [0]
            sub = cam.declare_subscriber(f"vpp/{RIG}/out/disparity", lambda s: results.__setitem__(0, results[0] + 1))
            pub = cam.declare_publisher(
                f"vpp/{RIG}/in/frame",
                congestion_control=zenoh.CongestionControl.BLOCK,
                reliability=zenoh.Reliability.RELIABLE,
            )
            time.sleep(0.5)
            rss.append(_rss_mb(proc.pid))
            stop_rss = threading.Event()

            def sample_rss() -> None:
                while not stop_rss.wait(0.5):
                    rss.append(_rss_mb(proc.pid))

            sampler = threading.Thread(target=sample_rss, daemon=True)
            sampler.start()
            if junk:
                flooder = threading.Thread(target=_flood, args=(conf, junk, flood_stop, junk_sent), daemon=True)
                flooder.start()
            period = 1.0 / rate_hz if rate_hz > 0 else 0.0
            t0 = time.monotonic()
            sent = 0
            warm_rss: float | None = None
            while time.monotonic() - t0 < seconds:
                if warm_rss is None and time.monotonic() - t0 > min(5.0, seconds / 4):
                    warm_rss = _rss_mb(proc.pid)  # after warm-up: buffers and caches are allocated
                data = bytearray(payloads[sent % len(payloads)])
                pub.put(_with_seq(data, sent))
                sent += 1
                delay = t0 + sent * period - time.monotonic()
                if period and delay > 0:
                    time.sleep(delay)
            publish_s = time.monotonic() - t0
            flood_stop.set()
            warm = warm_rss if warm_rss is not None else rss[-1]
            # drain: wait until the service has processed everything it will process
            last, still = -1, time.monotonic()
            while time.monotonic() - still < 3.0:
                st = _status(cam)
                done = int(st["counters"]["processed"]) if st else last  # type: ignore[index]
                if done != last:
                    last, still = done, time.monotonic()
                if done >= sent:
                    break
                time.sleep(0.3)
            st = _status(cam) or {}
            elapsed_s = time.monotonic() - t0  # publishing and draining
            stop_rss.set()
            sampler.join()
            pub.undeclare()
            sub.undeclare()
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            code = proc.wait(30)
        except subprocess.TimeoutExpired:
            proc.kill()
            code = proc.wait()
        log.close()
    summary = json.loads((out / "summary.json").read_text())
    c = summary["counters"]
    lat = summary["timing_ms"].get("latency", {})
    return {
        "policy": name,
        "junk_sent": junk_sent[0],
        "rejected": c["rejected"],
        "seconds": seconds,
        "offered_hz": rate_hz,
        "achieved_publish_hz": sent / publish_s,
        "publish_s": publish_s,
        "elapsed_s": elapsed_s,
        "sent": sent,
        "received": c["received"],
        "processed": c["processed"],
        "results_seen": results[0],
        "lost": sent - c["processed"],
        "dropped": c["dropped"],
        "dropped_by_cause": {k: v for k, v in summary["dropped"].items() if v},
        "all_losses_counted": sent - c["processed"] == c["dropped"],
        "latency_p50_ms": lat.get("p50"),
        "latency_p99_ms": lat.get("p99"),
        "rss_idle_mb": rss[0],
        "rss_warm_mb": warm,
        "rss_peak_mb": max(rss),
        "rss_end_mb": rss[-1],
        "rss_growth_pct": 100.0 * (rss[-1] - warm) / warm,
        "exit_code": code,
        "status_at_end": {"counters": st.get("counters"), "dropped": st.get("dropped")},
    }


def _flood(conf: zenoh.Config, junk: list[bytes], stop: threading.Event, sent: list[int]) -> None:
    """An attacker's session: junk on the frame key, as fast as it goes, until ``stop``."""
    with zenoh.open(conf) as attacker:
        pub = attacker.declare_publisher(f"vpp/{RIG}/in/frame", congestion_control=zenoh.CongestionControl.DROP)
        while not stop.is_set():
            pub.put(junk[sent[0] % len(junk)])
            sent[0] += 1


def _junk_messages(valid: bytes) -> list[bytes]:
    """Messages the service must reject: truncated, wrong types, non-finite calibration, lying sizes, no map."""
    import msgpack

    good = msgpack.unpackb(valid, raw=False)
    return [
        valid[: len(valid) // 2],
        msgpack.packb({**good, "seq": "seven"}, use_bin_type=True),
        msgpack.packb({**good, "calib": {"f": float("nan"), "baseline": 0.1}}, use_bin_type=True),
        msgpack.packb({**good, "left": {**good["left"], "h": 1 << 20}}, use_bin_type=True),
        msgpack.packb({**good, "v": 9}, use_bin_type=True),
        msgpack.packb([1, 2, 3]),
        b"\xc1" * 64,
    ]


def _with_seq(data: bytearray, seq: int) -> bytes:
    """The frame message with its ``seq`` replaced (msgpack re-pack of the small header only)."""
    import msgpack

    msg = msgpack.unpackb(bytes(data), raw=False)
    msg["seq"] = seq
    msg["stamp_ns"] = time.time_ns()
    return msgpack.packb(msg, use_bin_type=True)


def _parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seconds", type=float, default=120.0, help="publishing time per policy")
    p.add_argument("--factor", type=float, default=3.0, help="offered rate / processing rate")
    p.add_argument("--calibrate-s", type=float, default=8.0, help="unpaced run measuring the processing rate")
    p.add_argument("--height", type=int, default=240)
    p.add_argument("--width", type=int, default=320)
    p.add_argument("--matcher", default="sgbm")
    p.add_argument("--policies", nargs="+", default=["latest", "block"], choices=["latest", "block"])
    p.add_argument("--junk", action="store_true", help="also: valid frames at --junk-valid-hz under a junk flood")
    p.add_argument("--junk-valid-hz", type=float, default=10.0)
    p.add_argument("--junk-only", action="store_true", help="only the junk-flood runs (no calibration, no overload)")
    p.add_argument(
        "--json", default=str(Path(tempfile.gettempdir()) / "vpp-overload.json"), help="report path (not committed)"
    )
    return p.parse_args(argv)


def main(argv: Sequence[str] | None = None) -> int:
    """Calibrate, run each policy, print the table and write the JSON report."""
    a = _parse_args(argv)
    payloads = _frames(a)
    cal: dict[str, object] | None = None
    fps = rate = float("nan")
    rows: list[dict[str, object]] = []
    with tempfile.TemporaryDirectory() as d:
        if not a.junk_only:
            # the service's own rate: lossless and unpaced, the camera is held back to exactly what it processes
            cal = _run(a, "block", payloads, rate_hz=0.0, tmp=Path(d), seconds=a.calibrate_s)
            fps = float(cal["processed"]) / float(cal["elapsed_s"])  # frames buffered at the end count, with their time
            rate = a.factor * fps
            print(f"service processes {fps:.1f} fps (unpaced block run, {a.calibrate_s:g} s) -> offering {rate:.1f} Hz")
            rows += [_run(a, p, payloads, rate_hz=rate, tmp=Path(d), seconds=a.seconds) for p in a.policies]
        if a.junk or a.junk_only:
            junk = _junk_messages(payloads[0])
            rows += [
                _run(a, p, payloads, rate_hz=a.junk_valid_hz, tmp=Path(d), seconds=a.seconds, junk=junk)
                for p in a.policies
            ]
    head = f"{'policy':11} {'sent':>6} {'proc':>6} {'lost':>6} {'dropped':>7} {'counted':>7} {'pub Hz':>7} " + (
        f"{'lat p50':>8} {'lat p99':>8} {'RSS warm':>8} {'peak':>6} {'end':>6} {'growth':>7}  causes"
    )
    print(head)
    for r in rows:
        print(
            f"{r['policy']:11} {r['sent']:6d} {r['processed']:6d} {r['lost']:6d} {r['dropped']:7d} "
            f"{'yes' if r['all_losses_counted'] else 'NO':>7} {r['achieved_publish_hz']:7.1f} "
            f"{r['latency_p50_ms'] or float('nan'):8.0f} {r['latency_p99_ms'] or float('nan'):8.0f} "
            f"{r['rss_warm_mb']:8.0f} {r['rss_peak_mb']:6.0f} {r['rss_end_mb']:6.0f} {r['rss_growth_pct']:6.1f}%  "
            f"{r['dropped_by_cause']}"
        )
    path = write_report(
        a.json, rows, processing_fps=fps, offered_hz=rate, factor=a.factor, size=[a.height, a.width], calibration=cal
    )
    for r in rows:
        if r["junk_sent"]:
            print(
                f"junk flood ({r['policy']}): {r['junk_sent']} junk messages sent, {r['rejected']} rejected; "
                f"valid frames at "
                f"{a.junk_valid_hz:g} Hz: {r['processed']}/{r['sent']} processed "
                f"({100.0 * int(r['processed']) / max(1, int(r['sent'])):.1f} %)"
            )
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
