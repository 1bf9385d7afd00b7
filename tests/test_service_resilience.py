"""The service (client mode, behind a Zenoh router) survives a router restart and stops cleanly under load.

Real parts: a router process that is SIGKILLed and started again on the same
port, the service as ``python -m vpp_service run`` from this checkout (Zenoh
source, SGBM, zenoh and files sinks), and a camera + output subscriber in this
process. Behaviour only, generous timeouts: how fast outputs resume and how fast
the service exits is measured by ``benchmarks/resilience.py``.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import zenoh

from helpers.frames import make_frame
from helpers.zenoh_loopback import free_port, zenoh_test_config
from helpers.zenoh_router import RouterProcess
from vpp_service.transport import wire

ROOT = Path(__file__).resolve().parents[1]
RIG = "resil"


def _service_config(tmp_path: Path, endpoint: str) -> Path:
    cfg = tmp_path / "service.toml"
    cfg.write_text(f"""
[service]
rig = "{RIG}"
out = "{tmp_path / "run"}"
summary = false
shutdown_timeout_s = 5.0
[zenoh]
mode = "client"
listen = []
connect = ["{endpoint}"]
[source]
type = "zenoh"
[matcher]
name = "sgbm"
max_disparity = 16
[queues]
input_policy = "latest"
output_policy = "block"
[[sinks]]
type = "zenoh"
outputs = ["disparity"]
[[sinks]]
type = "files"
dir = "{tmp_path / "run" / "frames"}"
create_dir = true
""")
    return cfg


class _Camera:
    """Frames of the served rig, reliable and BLOCK, each with a new seq, at ``rate_hz`` (0 = unpaced)."""

    def __init__(self, session: zenoh.Session) -> None:
        self.pub = session.declare_publisher(
            f"vpp/{RIG}/in/frame",
            congestion_control=zenoh.CongestionControl.BLOCK,
            reliability=zenoh.Reliability.RELIABLE,
        )
        self.msgs = [wire.encode_frame(make_frame(h=48, w=64, seed=i).with_(rig=RIG, seq=i)) for i in range(4)]
        self.sent = 0
        self.stop = threading.Event()
        self.thread: threading.Thread | None = None

    def _loop(self, rate_hz: float) -> None:
        while not self.stop.is_set():
            frame = wire.decode_frame(self.msgs[self.sent % len(self.msgs)]).with_(seq=self.sent)
            self.pub.put(wire.encode_frame(frame))
            self.sent += 1
            if rate_hz:
                self.stop.wait(1.0 / rate_hz)

    def start(self, rate_hz: float) -> None:
        self.stop.clear()
        self.thread = threading.Thread(target=self._loop, args=(rate_hz,), daemon=True)
        self.thread.start()

    def halt(self) -> None:
        self.stop.set()
        if self.thread is not None:
            self.thread.join(10)


def _outputs_after(times: list[float], t: float, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if times and times[-1] > t:
            return True
        time.sleep(0.02)
    return False


def test_outputs_resume_after_router_restart_and_sigterm_under_load_flushes_the_sinks(tmp_path: Path) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    with RouterProcess(endpoint) as router:
        router.start()
        log = (tmp_path / "service.log").open("wb")
        proc = subprocess.Popen(
            [sys.executable, "-m", "vpp_service", "run", "--config", str(_service_config(tmp_path, endpoint))],
            cwd=ROOT,
            env=env,
            stdout=log,
            stderr=log,
        )
        try:
            with zenoh.open(zenoh_test_config(connect=[endpoint], mode="client")) as session:
                times: list[float] = []
                session.declare_subscriber(f"vpp/{RIG}/out/disparity", lambda _s: times.append(time.monotonic()))
                cam = _Camera(session)
                cam.start(10.0)
                assert _outputs_after(times, 0.0, 60.0), "no output before the restart"
                router.kill()
                time.sleep(2.0)
                router.start()
                back = time.monotonic()
                assert _outputs_after(times, back, 30.0), "outputs never resumed after the router restart"
                cam.halt()
                # SIGTERM while the camera offers frames as fast as BLOCK lets it (more than the service takes)
                cam.start(0.0)
                time.sleep(2.0)
                proc.send_signal(signal.SIGTERM)
                code = proc.wait(60)
                cam.halt()
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
            log.close()
    assert code == 0, (tmp_path / "service.log").read_text()
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    c = summary["counters"]
    files = sorted((tmp_path / "run" / "frames").glob(f"{RIG}_*_disparity.png"))
    assert c["processed"] > 0 and c["errors"] == 0
    # every processed result reached the sinks (output policy block), and every one is on disk
    assert len(files) == c["published"] == c["processed"] == summary["sinks"]["FilesSink"]["written"]
    assert summary["sinks"]["FilesSink"]["errors"] == 0
