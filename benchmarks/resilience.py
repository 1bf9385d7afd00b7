"""Resilience on loopback: router kill/restart and SIGTERM under load.

One Zenoh router (a ``python -c`` subprocess holding a session in ``router``
mode, so it can be SIGKILLed), one service (``python -m vpp_service run``,
client mode connected to the router, Zenoh source, small SGBM, files sink), and
this process: a camera publishing frames of the served rig reliably with
``CongestionControl.BLOCK`` and a subscriber on the outputs, both on one client
session connected to the router.

(a) Router kill/restart, ``--restarts`` times: with the camera at ``--rate-hz``,
the router is SIGKILLed, restarted on the same port after ``--down-s`` seconds,
and the time from the restarted router being ready (its session open) to the
next output received is measured. The issue's bound: <= 5 s.

(b) SIGTERM under load: the service's rate is measured (the camera publishing
unpaced for ``--calibrate-s``), then the camera offers ``--factor`` times that
rate for ``--load-s`` seconds and the service gets SIGTERM while frames keep
coming. Reported: time to exit, exit code, and whether the files sink wrote
every result the service counted (summary.json ``published``/``processed`` and
the sink's ``written`` vs the files on disk). The issue's bound: exit <= 5 s,
code 0, sinks flushed.

Prints a table and writes JSON (default ``out/benchmarks/resilience.json``; never
into the committed ``benchmarks/results/``).

    python benchmarks/resilience.py
    python benchmarks/resilience.py --restarts 5 --json /tmp/resilience.json
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import cast

from _harness import SCRATCH, write_report

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))  # the router process and loopback configs are shared with the tests

import msgpack  # noqa: E402
import zenoh  # noqa: E402

from helpers.zenoh_loopback import free_port, zenoh_test_config  # noqa: E402
from helpers.zenoh_router import RouterProcess  # noqa: E402
from vpp_service.service.app import CONNECT_RETRY  # noqa: E402
from vpp_service.sources.base import SourceContext, build_source  # noqa: E402
from vpp_service.sources.sim import SimSource  # noqa: E402
from vpp_service.transport import wire  # noqa: E402

RIG = "res"


def _client_config(endpoint: str) -> zenoh.Config:
    conf = zenoh_test_config(connect=[endpoint], mode="client")
    conf.insert_json5("connect/retry", json.dumps(CONNECT_RETRY))  # reconnect at the service's pace
    return conf


def _toml_value(v: object) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return json.dumps(v)


def _service_toml(endpoint: str, out: Path, max_disparity: int) -> str:
    sections: dict[str, Mapping[str, object]] = {
        "service": {"rig": RIG, "out": str(out), "summary": False, "shutdown_timeout_s": 5.0},
        "zenoh": {"mode": "client", "listen": [], "connect": [endpoint]},
        "source": {"type": "zenoh", "ring_size": 4},
        "matcher": {"name": "sgbm", "max_disparity": max_disparity},
        "queues": {"input_size": 2, "input_policy": "latest", "output_size": 4, "output_policy": "block"},
    }
    text = "".join(
        f"[{name}]\n" + "".join(f"{k} = {_toml_value(v)}\n" for k, v in sec.items()) for name, sec in sections.items()
    )
    text += '[[sinks]]\ntype = "zenoh"\noutputs = ["disparity"]\n'
    text += f'[[sinks]]\ntype = "files"\ndir = {json.dumps(str(out / "frames"))}\ncreate_dir = true\n'
    return text


class Camera:
    """Frames of the served rig on ``vpp/<rig>/in/frame`` (reliable, BLOCK), each with a new ``seq``."""

    def __init__(self, session: zenoh.Session, height: int, width: int) -> None:
        src = build_source(
            "sim",
            {"scene": "synthetic", "scene_options": {"height": height, "width": width, "max_disparity": 32}},
            SourceContext(rig=RIG),
        )
        assert isinstance(src, SimSource)
        src.open()
        self.msgs = [msgpack.unpackb(wire.encode_frame(src.frame(i)), raw=False) for i in range(4)]
        self.pub = session.declare_publisher(
            f"vpp/{RIG}/in/frame",
            congestion_control=zenoh.CongestionControl.BLOCK,
            reliability=zenoh.Reliability.RELIABLE,
        )
        self.sent = 0

    def put(self) -> None:
        """Publish the next frame."""
        msg = dict(self.msgs[self.sent % len(self.msgs)], seq=self.sent, stamp_ns=time.time_ns())
        self.pub.put(msgpack.packb(msg, use_bin_type=True))
        self.sent += 1

    def run(self, rate_hz: float, stop: threading.Event) -> None:
        """Publish at ``rate_hz`` (0 = as fast as the BLOCK publisher goes) until ``stop``."""
        t0, n = time.monotonic(), 0
        while not stop.is_set():
            self.put()
            n += 1
            if rate_hz > 0:
                delay = t0 + n / rate_hz - time.monotonic()
                if delay > 0:
                    stop.wait(delay)


class Outputs:
    """Receive times of ``vpp/<rig>/out/disparity`` samples."""

    def __init__(self, session: zenoh.Session) -> None:
        self.times: list[float] = []
        self.sub = session.declare_subscriber(
            f"vpp/{RIG}/out/disparity", lambda _s: self.times.append(time.monotonic())
        )

    def first_after(self, t: float, timeout: float) -> float | None:
        """Monotonic time of the first output received after ``t`` (None if none within ``timeout`` of now)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            later = [x for x in self.times[-50:] if x > t]
            if later:
                return later[0]
            time.sleep(0.005)
        return None


def _run(a: argparse.Namespace, tmp: Path) -> dict[str, object]:  # noqa: PLR0915 - the scenario, step by step
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = RouterProcess(endpoint)
    router.start()
    out = tmp / "out"
    cfg = tmp / "service.toml"
    cfg.write_text(_service_toml(endpoint, out, a.max_disparity))
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    log = (tmp / "service.log").open("wb")
    proc = subprocess.Popen(
        [sys.executable, "-m", "vpp_service", "run", "--config", str(cfg)], cwd=REPO, env=env, stderr=log, stdout=log
    )
    restarts: list[dict[str, float | None]] = []
    result: dict[str, object] = {}
    try:
        with zenoh.open(_client_config(endpoint)) as session:
            outputs = Outputs(session)
            cam = Camera(session, a.height, a.width)
            stop = threading.Event()
            feeder = threading.Thread(target=cam.run, args=(a.rate_hz, stop), daemon=True)
            feeder.start()
            if outputs.first_after(0.0, 60.0) is None:
                raise RuntimeError(f"no output within 60 s of start (see {tmp / 'service.log'})")
            # (a) router kill/restart
            for _ in range(a.restarts):
                time.sleep(a.settle_s)
                router.kill()
                killed = time.monotonic()
                time.sleep(a.down_s)
                router.start()
                back = time.monotonic()  # its session is open
                first = outputs.first_after(back, a.resume_timeout_s)
                restarts.append({"down_s": back - killed, "resume_s": None if first is None else first - back})
            stop.set()
            feeder.join()
            # (b) SIGTERM under load: the service's rate first, then factor x that rate
            time.sleep(1.0)
            n0 = len(outputs.times)
            stop = threading.Event()
            feeder = threading.Thread(target=cam.run, args=(0.0, stop), daemon=True)
            t0 = time.monotonic()
            feeder.start()
            time.sleep(a.calibrate_s)
            service_hz = (len(outputs.times) - n0) / (time.monotonic() - t0)
            stop.set()
            feeder.join()
            load_hz = a.factor * service_hz
            stop = threading.Event()
            feeder = threading.Thread(target=cam.run, args=(load_hz, stop), daemon=True)
            feeder.start()
            time.sleep(a.load_s)
            term = time.monotonic()
            proc.send_signal(signal.SIGTERM)
            try:
                code = proc.wait(60)
            except subprocess.TimeoutExpired:
                proc.kill()
                code = proc.wait()
            exit_s = time.monotonic() - term
            stop.set()
            feeder.join()
            result = {"service_hz": service_hz, "load_hz": load_hz, "exit_s": exit_s, "exit_code": code}
            result["frames_sent"] = cam.sent
            result["outputs_received"] = len(outputs.times)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        log.close()
        router.kill()
    summary = json.loads((out / "summary.json").read_text())
    c = summary["counters"]
    files = len(list((out / "frames").glob(f"{RIG}_*_disparity.png")))
    sink = summary["sinks"].get("FilesSink", {})
    resumes = [r["resume_s"] for r in restarts]
    return {
        "restarts": restarts,
        "resume_max_s": None if None in resumes or not resumes else max(r for r in resumes if r is not None),
        **result,
        "summary_shutdown_s": summary["shutdown_s"],
        "counters": c,
        "dropped_by_cause": {k: v for k, v in summary["dropped"].items() if v},
        "files_written_counter": sink.get("written"),
        "files_errors": sink.get("errors"),
        "files_on_disk": files,
        "flushed": files == c["published"] == c["processed"] == sink.get("written"),
    }


def _parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--restarts", type=int, default=3, help="router kill/restart cycles")
    p.add_argument("--down-s", type=float, default=2.0, help="router down time per cycle")
    p.add_argument("--settle-s", type=float, default=2.0, help="normal running before each kill")
    p.add_argument("--resume-timeout-s", type=float, default=60.0, help="give up waiting for outputs after this")
    p.add_argument("--rate-hz", type=float, default=10.0, help="camera rate during the restarts")
    p.add_argument("--calibrate-s", type=float, default=4.0, help="unpaced publishing measuring the service's rate")
    p.add_argument("--factor", type=float, default=3.0, help="offered rate / service rate before SIGTERM")
    p.add_argument("--load-s", type=float, default=5.0, help="time under load before SIGTERM")
    p.add_argument("--height", type=int, default=120)
    p.add_argument("--width", type=int, default=160)
    p.add_argument("--max-disparity", type=int, default=32)
    p.add_argument("--json", type=Path, default=SCRATCH / "resilience.json", help="report path (not committed)")
    return p.parse_args(argv)


def main(argv: Sequence[str] | None = None) -> int:
    """Run both scenarios, print the table, write the JSON report."""
    a = _parse_args(argv)
    with tempfile.TemporaryDirectory() as d:
        r = _run(a, Path(d))
    print(f"{'router restart':16} {'down s':>7} {'outputs again after s':>22}")
    restarts = cast(list[dict[str, float | None]], r["restarts"])
    for i, x in enumerate(restarts):
        resume = "never" if x["resume_s"] is None else f"{x['resume_s']:.2f}"
        print(f"{i + 1:16d} {x['down_s'] or 0.0:7.2f} {resume:>22}")
    print(f"max resume after the router returns: {r['resume_max_s']} s (bound 5 s)")
    print(
        f"SIGTERM at {r['load_hz']:.1f} Hz offered ({a.factor:g}x the service's {r['service_hz']:.1f} fps): "
        f"exit after {r['exit_s']:.2f} s (bound 5 s), code {r['exit_code']}; "
        f"processed {r['counters']['processed']} published {r['counters']['published']} "  # type: ignore[index]
        f"files sink wrote {r['files_written_counter']} ({r['files_errors']} errors), "
        f"{r['files_on_disk']} on disk -> flushed: {r['flushed']}"
    )
    path = write_report(a.json, [r], size=[a.height, a.width], rate_hz=a.rate_hz, factor=a.factor)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
