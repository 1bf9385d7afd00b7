"""A rig's worker pool on loopback for tests and benchmarks: a router, workers, a publisher, in processes.

Workers are ``python -m vpp_service run --pool`` (the checkout's code, see
:func:`helpers.cli.vpp_service_module_command`) in Zenoh client mode behind one
router (:class:`helpers.zenoh_router.RouterProcess`), like hosts of a fleet.
"""

from __future__ import annotations

import os
import subprocess
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from helpers.cli import vpp_service_module_command

if TYPE_CHECKING:
    import zenoh

ROOT = Path(__file__).resolve().parents[2]


def worker_config(
    folder: Path,
    endpoint: str,
    rig: str,
    worker_id: str,
    *,
    matcher: str = 'name = "sgbm"\nmax_disparity = 48',
    deadline_ms: float = 1000.0,
    sinks: str = '[[sinks]]\ntype = "zenoh"\noutputs = ["disparity"]\non_request = []\n',
    input_size: int = 16,
) -> Path:
    """Write the TOML config of one pool worker (client of the router at ``endpoint``); returns its path."""
    cfg = folder / f"{worker_id}.toml"
    cfg.write_text(f"""
[service]
rig = "{rig}"
out = "{folder / worker_id}"
pool = true
worker_id = "{worker_id}"
pool_deadline_ms = {deadline_ms}
summary_period_s = 0.5
shutdown_timeout_s = 3.0
[zenoh]
mode = "client"
listen = []
connect = ["{endpoint}"]
[source]
type = "zenoh"
ring_size = 16
[matcher]
{matcher}
[queues]
input_size = {input_size}
input_policy = "block"
output_size = 16
output_policy = "block"
{sinks}
""")
    return cfg


def start_worker(
    cfg: Path,
    log: Path | None = None,
    env: dict[str, str] | None = None,
    wrap: Callable[[list[str]], list[str]] | None = None,
) -> subprocess.Popen[bytes]:
    """Start one worker from ``cfg`` (stderr to ``log``, else discarded; ``env`` added to the environment).

    ``wrap`` turns the command into the one to run (e.g. inside a network namespace).
    """
    env = {**os.environ, "PYTHONUNBUFFERED": "1", **(env or {})}
    err = open(log, "wb") if log is not None else subprocess.DEVNULL  # noqa: SIM115 - the child owns it
    argv = [*vpp_service_module_command(), "run", "--config", str(cfg)]
    return subprocess.Popen(
        wrap(argv) if wrap is not None else argv,
        cwd=ROOT,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=err,
    )


def wait_members(
    session: zenoh.Session, rig: str, n: int, procs: list[subprocess.Popen[bytes]], timeout: float = 30.0
) -> list[str]:
    """Wait until ``n`` workers hold their ``@pool`` token; returns their ids.

    Raises
    ------
    RuntimeError
        A worker exited, or fewer than ``n`` appeared within ``timeout``.
    """
    deadline = time.monotonic() + timeout
    seen: list[str] = []
    while time.monotonic() < deadline:
        for p in procs:
            if p.poll() is not None:
                raise RuntimeError(f"a worker exited with {p.returncode}")
        seen = sorted(
            str(r.ok.key_expr).rsplit("/", 1)[-1]
            for r in session.liveliness().get(f"vpp/{rig}/@pool/*", timeout=1.0)
            if r.ok is not None
        )
        if len(seen) >= n:
            # each worker subscribed to in/frame before declaring its token; let the routes settle
            time.sleep(0.5)
            return seen
        time.sleep(0.1)
    raise RuntimeError(f"only {seen} joined the pool within {timeout} s")


def publish(
    endpoint: str, rig: str, count: int, *, rate: float = 0.0, scale: float = 0.25, seed: int = 0
) -> subprocess.CompletedProcess[str]:
    """Publish ``count`` simulated frames (raw images) on ``rig`` through the router; waits for the end."""
    cmd = [
        *vpp_service_module_command(),
        "publish",
        "--scale", str(scale),
        "--count", str(count),
        "--rate", str(rate),
        "--rig", rig,
        "--connect", endpoint,
        "--enc", "raw",
        "--seed", str(seed),
    ]  # fmt: skip
    return subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=120, check=False)


def stop_all(procs: list[subprocess.Popen[bytes]], timeout: float = 10.0) -> list[int | None]:
    """SIGTERM every worker still running, wait for each (SIGKILL past ``timeout``); their exit codes."""
    for p in procs:
        if p.poll() is None:
            p.terminate()
    codes: list[int | None] = []
    for p in procs:
        try:
            codes.append(p.wait(timeout))
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()
            codes.append(None)
    return codes


def attack(
    hostile: zenoh.Session, rig: str, workers: list[str], count: int, fakes: int = 6
) -> list[zenoh.LivelinessToken]:
    """Attack a pool as a hostile peer; returns the fake tokens (members while they are held).

    ``fakes`` ``@pool`` tokens that never speak, and ``@answered`` forged for seq 0 .. count-1 under
    every id of ``workers`` and an id without a token ("intruder").
    """
    from vpp_service.service.pool import encode_answered

    tokens = [hostile.liveliness().declare_token(f"vpp/{rig}/@pool/fake{i}") for i in range(fakes)]
    forger = hostile.declare_publisher(f"vpp/{rig}/@answered")
    time.sleep(0.5)  # the tokens reach the workers before the answers
    for seq in range(count):
        for w in [*workers, "intruder"]:
            forger.put(encode_answered(rig, seq, w))
    return tokens
