"""End to end: installed ``vpp-service publish`` -> Zenoh on 127.0.0.1 -> ``vpp-service run`` -> a test subscriber.

Every received disparity is checked against ground truth: bad-2 must be well
below the no-depth baseline of the same matcher; ``@status`` counters must
match what was sent (including one malformed message, rejected); SIGINT /
SIGTERM shut the service down cleanly (exit 0) within a bound.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

from helpers.cli import vpp_service_command
from helpers.zenoh_loopback import free_port, zenoh_test_config

ROOT = Path(__file__).resolve().parents[1]
SCALE = 0.5
COUNT = 5
MAXD = 48


def service_config(tmp_path: Path, port: int, rig: str, source_extra: str = "") -> Path:
    cfg = tmp_path / "service.toml"
    cfg.write_text(f"""
[service]
rig = "{rig}"
out = "{tmp_path / "run"}"
summary_period_s = 0.5
shutdown_timeout_s = 3.0
[zenoh]
listen = ["tcp/127.0.0.1:{port}"]
[source]
type = "zenoh"
ring_size = 16
{source_extra}
[matcher]
name = "sgbm"
max_disparity = {MAXD}
fill = true
[queues]
input_size = 16
input_policy = "block"
output_size = 16
output_policy = "block"
[[sinks]]
type = "zenoh"
outputs = ["disparity", "depth"]
""")
    return cfg


def start_service(cfg: Path) -> subprocess.Popen:
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    return subprocess.Popen(
        [*vpp_service_command(), "run", "--config", str(cfg)],
        cwd=ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def wait_alive(session, key: str, proc: subprocess.Popen, timeout: float = 20.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            pytest.fail(f"service exited early: {proc.communicate()}")
        if any(r.ok is not None for r in session.liveliness().get(key, timeout=0.5)):
            return
        time.sleep(0.1)
    pytest.fail("service never declared @alive")


def query_status(session, key: str) -> dict:
    for r in session.get(key, timeout=3.0):
        if r.ok is not None:
            return json.loads(r.ok.payload.to_string())
    raise AssertionError("no @status reply")


@pytest.fixture(scope="module")
def baseline_bad2() -> tuple[float, np.ndarray]:
    """bad-2 of the same matcher on the raw pair (no depth), and the GT."""
    from vpp_service.matchers import build_matcher
    from vpp_service.metrics import compute_metrics
    from vpp_service.sources.sim import motorcycle_frame

    fr = motorcycle_frame(SCALE)
    disp = build_matcher("sgbm", {"max_disparity": MAXD, "fill": True}).compute(fr.left, fr.right)
    return compute_metrics(disp, fr.gt_disparity)["bad2"], fr.gt_disparity


def collect(sub, n: int, timeout: float) -> list:
    out = []
    deadline = time.monotonic() + timeout
    while len(out) < n and time.monotonic() < deadline:
        s = sub.try_recv()
        if s is None:
            time.sleep(0.01)
            continue
        out.append(s.payload.to_bytes())
    return out


@pytest.mark.parametrize(("mode", "sig"), [("frame", signal.SIGINT), ("separate", signal.SIGTERM)])
def test_publisher_to_service_to_subscriber(tmp_path, baseline_bad2, mode, sig):
    import zenoh

    from vpp_service.metrics import compute_metrics
    from vpp_service.transport import wire

    base, gt = baseline_bad2
    port = free_port()
    rig = f"e2e{mode}"
    extra = 'topics = "separate"\nsync = "approximate"\nsync_threshold_ms = 5.0' if mode == "separate" else ""
    proc = start_service(service_config(tmp_path, port, rig, extra))
    try:
        with zenoh.open(zenoh_test_config(connect=[f"tcp/127.0.0.1:{port}"])) as session:
            wait_alive(session, f"vpp/{rig}/@alive", proc)
            sub = session.declare_subscriber(f"vpp/{rig}/out/disparity", zenoh.handlers.FifoChannel(64))
            depth_sub = session.declare_subscriber(f"vpp/{rig}/out/depth", zenoh.handlers.FifoChannel(64))
            time.sleep(0.3)
            # one malformed message: rejected, counted, the service keeps serving
            bad_key = f"vpp/{rig}/in/frame" if mode == "frame" else f"vpp/{rig}/in/left"
            session.put(bad_key, b"\x85garbage", congestion_control=zenoh.CongestionControl.BLOCK)
            cmd = [
                *vpp_service_command(),
                "publish",
                "--scale",
                str(SCALE),
                "--count",
                str(COUNT),
                "--rate",
                "5",
                "--density",
                "0.1",
                "--rig",
                rig,
                "--connect",
                f"tcp/127.0.0.1:{port}",
                "--enc",
                "png",
            ]
            if mode == "separate":
                cmd.append("--separate-topics")
            pub = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=60, check=False)
            assert pub.returncode == 0, pub.stderr
            assert json.loads(pub.stdout.strip().splitlines()[-1])["sent"] == COUNT
            msgs = collect(sub, COUNT, timeout=30)
            depths = collect(depth_sub, COUNT, timeout=5)
            assert len(msgs) == COUNT and len(depths) == COUNT
            seqs = []
            for payload in msgs:
                out = wire.decode_output(payload)
                seqs.append(out.seq)
                bad2 = compute_metrics(out.data, gt)["bad2"]
                assert bad2 < 0.8 * base, (bad2, base)  # ~0.72 measured (10 % points, SGBM)
                assert out.metrics["bad2"] == pytest.approx(bad2, abs=1e-6)  # service scored the same
                assert {"vpp", "match"} <= set(out.timing_ms)
            assert seqs == list(range(COUNT))
            d0 = wire.decode_output(depths[0])
            assert d0.calib is not None and np.nanmedian(d0.data) > 0
            st = query_status(session, f"vpp/{rig}/@status")
            c = st["counters"]
            assert c["rejected"] == 1 and c["processed"] == COUNT and c["published"] == COUNT
            assert c["dropped"] == 0 and c["no_depth"] == 0 and c["errors"] == 0
        t0 = time.monotonic()
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=15)
        assert proc.returncode == 0, err
        assert time.monotonic() - t0 < 10
        summary = json.loads((tmp_path / "run" / "summary.json").read_text())
        assert summary["counters"]["published"] == COUNT
        assert "fps" in err and "bad-2" in err
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
