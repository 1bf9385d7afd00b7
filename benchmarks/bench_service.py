"""Service benchmark: frames/s and end-to-end latency over loopback Zenoh vs the matcher alone.

At KITTI size (1242 x 375, a synthetic scene with a uniform 5 % sensor) it measures

(a) the matcher alone (SGBM, warm, in this process) on the exact VPP-painted
    pairs the service matches, interleaved with the paced run (right after each
    result, while the service idles) so both see the same background load;
(b) end-to-end latency, paced (``--rate`` Hz and one frame in flight: no
    queueing): camera put -> Zenoh (tcp/127.0.0.1) -> service decode -> VPP ->
    SGBM -> encode -> Zenoh -> client. The camera writes each encoded frame into
    a buffer of its own shared-memory pool first, as a driver capturing into
    shared memory would, and stamps it right before the put: that write is the
    camera's work, reported apart (``camera_shm.write_ms_p50``), not in the e2e;
(c) throughput, unpaced, with lossless ``block`` queues;
(d) the service's own stage timings, from its ``@status`` queryable and from the
    ``timing_ms`` carried by every ``out/disparity`` message (decode, vpp, match,
    process) and the Zenoh sink's encode / put times.

The service runs as its own process (``python -m vpp_service run --config
<tmp toml>``, Zenoh listening on a free 127.0.0.1 port, multicast scouting off);
the camera (publisher) and the result subscriber live in this process.

Overhead (the headline) = per frame, e2e minus the service's own match time,
p50 over the frames, against the matcher alone; per-stage breakdown (vpp,
decode, encode/put, transport = what is left of each frame's e2e after the
service's own stages: Zenoh both ways, queue hand-offs, the client), each a
per-frame p50. Also printed, unpaired: (e2e p50 - matcher p50) / matcher p50,
which also carries any drift of the matcher's own time between the two runs.

The two headline ratios (the service keeps pace when overhead <= 5 % and
throughput >= 0.95):

* ``overhead_pct``: the paired per-frame overhead above, in % of the matcher alone;
* ``throughput_ratio``: the unpaced run's steady frame rate (results 2..N over
  the time between the first and the last result) over the matcher alone's
  frame rate (1000 / its mean ms).

Also ``matcher_busy_ratio``: that steady frame rate times the service's own
mean match time in the same unpaced run, the share of the wall time its process
stage spends matching; it sees the same load as the frame rate, so it moves
less with the host's load than ``throughput_ratio`` (which compares two
different moments), but it does not see the matcher slowed by the service's
other threads.

``--runs N`` repeats everything (a fresh service process each time) and reports
every run plus the median, min and max of both ratios; the machine's load
varies, so quote the median and the spread.

    python benchmarks/bench_service.py --frames 40 --runs 3
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    import zenoh
    import zenoh.shm

    from vpp_service.frame import StereoFrame
    from vpp_service.matchers import Matcher

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))
from _harness import add_output_args, output_path  # noqa: E402 - after the path set-up above

RIG = "bench"
#: stamp_ns placeholder written by the encoder, patched in place before each put.
_SENTINEL = 0x7EDC_BA98_7654_3210


def _port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _toml(cfg: Mapping[str, Any]) -> str:
    """Minimal TOML writer for the flat tables / arrays of tables used here."""

    def val(v: object) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, (int, float)):
            return repr(v)
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, list):
            return "[" + ", ".join(val(x) for x in v) + "]"
        raise TypeError(type(v))

    lines = []
    for table, body in cfg.items():
        for entry in body if isinstance(body, list) else [body]:
            lines.append(f"[[{table}]]" if isinstance(body, list) else f"[{table}]")
            lines += [f"{k} = {val(v)}" for k, v in entry.items()]
            lines.append("")
    return "\n".join(lines)


def _pct(a: Sequence[float], q: float) -> float:
    """Percentile ``q`` of ``a`` (NaN when empty)."""
    return float(np.percentile(a, q)) if len(a) else float("nan")


def _parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=40, help="frames per run (paced and unpaced)")
    ap.add_argument("--runs", type=int, default=1, help="repeat the whole measurement N times (fresh service each)")
    ap.add_argument("--width", type=int, default=1242)
    ap.add_argument("--height", type=int, default=375)
    ap.add_argument("--max-disparity", type=int, default=128)
    ap.add_argument("--rate", type=float, default=5.0, help="paced run rate (Hz)")
    ap.add_argument("--warmup", type=int, default=3)
    ap.add_argument(
        "--source-poll-s",
        type=float,
        default=0.05,
        help="zenoh source idle poll period (service default 0.002; adds ~half of it to e2e)",
    )
    ap.add_argument(
        "--omp-spincount",
        type=int,
        default=0,
        metavar="N",
        help="run the service with GOMP_SPINCOUNT=N (OpenMP workers spin between frames "
        "instead of sleeping: lower latency, one core busy); 0 = the default policy",
    )
    ap.add_argument(
        "--shm-pool-mb",
        type=int,
        default=64,
        help="shared-memory pool of the camera's and the service's publishers "
        "(vpp_service.transport.shm); 0 = plain puts",
    )
    add_output_args(ap, "bench_service")
    return ap.parse_args(argv)


def _payloads(frames: list[StereoFrame]) -> list[tuple[bytearray, int]]:
    """Encoded frames with a placeholder stamp, and the offset where the stamp is patched before each put."""
    from vpp_service.transport import wire

    payloads: list[tuple[bytearray, int]] = []
    for f in frames:
        p = bytearray(wire.encode_frame(f.with_(stamp_ns=_SENTINEL), include_gt=False))
        off = p.find(b"\xcf" + struct.pack(">Q", _SENTINEL))
        if off < 0:
            raise RuntimeError("stamp placeholder not found in the encoded frame")
        payloads.append((p, off + 1))
    return payloads


def _start_service(
    raw_cfg: Mapping[str, Any], tmp: Path, a: argparse.Namespace
) -> tuple[subprocess.Popen[bytes], Path]:
    """Start ``python -m vpp_service run`` on ``raw_cfg`` (written as TOML under ``tmp``); return it and its log."""
    toml_path = tmp / "service.toml"
    toml_path.write_text(_toml(raw_cfg))
    log_path = tmp / "service.log"
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    if a.omp_spincount:  # low-latency mode: OpenMP workers spin between frames
        env.pop("OMP_WAIT_POLICY", None)
        env["GOMP_SPINCOUNT"] = str(a.omp_spincount)
    with open(log_path, "w") as log:
        proc = subprocess.Popen(
            [sys.executable, "-m", "vpp_service", "run", "--config", str(toml_path)],
            cwd=str(REPO),
            stdout=log,
            stderr=subprocess.STDOUT,
            env=env,
        )
    return proc, log_path


def _stop_service(proc: subprocess.Popen[bytes]) -> None:
    """Stop the service like Ctrl-C does (killed after 15 s)."""
    proc.send_signal(signal.SIGINT)
    try:
        proc.wait(15)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


@dataclass
class _Runs:
    """What the client measured: latencies (ms), the service's per-frame stages, its status, the matcher alone."""

    paced: list[float]
    paced_stages: list[dict[str, float]]
    matcher_ms: list[float]
    throughput_latency: list[float]
    fps: float
    fps_steady: float
    status_paced: dict[str, Any]
    status_throughput: dict[str, Any]
    camera_shm: dict[str, Any]


class _Camera:
    """The client side in this process: publishes the frames, collects the results' latency and stage timings."""

    def __init__(self, cli: zenoh.Session, payloads: list[tuple[bytearray, int]], shm_pool_mb: int) -> None:
        import zenoh

        from vpp_service.transport import wire

        self.cli, self.payloads = cli, payloads
        self.status_key = wire.topic("vpp", RIG, "@status")
        self.latency: list[float] = []
        self.stages: list[dict[str, float]] = []
        self.got = threading.Semaphore(0)
        self.t_last = 0.0
        self.pool = _camera_pool(shm_pool_mb)
        self.shm_puts = self.plain_puts = self.fallbacks = 0
        #: ms the camera takes to write each frame into its pool buffer (before the stamp; not in the e2e)
        self.write_ms: list[float] = []
        self.sub = cli.declare_subscriber(wire.topic("vpp", RIG, "out/disparity"), self._on_out)
        self.pub = cli.declare_publisher(
            wire.topic("vpp", RIG, "in/frame"), congestion_control=zenoh.CongestionControl.BLOCK
        )

    def _on_out(self, sample: zenoh.Sample) -> None:
        from vpp_service.transport import wire

        now = time.time_ns()
        msg = wire.unpack(sample.payload.to_bytes())
        self.latency.append((now - msg["stamp_ns"]) / 1e6)
        self.stages.append(dict(msg.get("timing_ms", {})))
        self.t_last = time.perf_counter()
        self.got.release()

    def query_status(self, timeout: float = 3.0) -> dict[str, Any] | None:
        """The service's ``@status`` (None when it does not reply)."""
        for reply in self.cli.get(self.status_key, timeout=timeout):
            if reply.ok is not None:
                status: dict[str, Any] = json.loads(reply.ok.payload.to_string())
                return status
        return None

    def send(self, i: int) -> None:
        """Publish frame ``i`` (modulo the unique ones), stamped right before the put.

        Like a camera driver that captures into shared memory, the camera first
        writes the frame into a buffer from its own pool (its own work, timed in
        ``write_ms``, not part of the e2e), then stamps it there and puts it.
        Without a pool (or when the pool cannot serve it) the bytes are stamped
        and put plainly, and Zenoh's copy inside the put counts as transport.
        """
        buf, off = self.payloads[i % len(self.payloads)]
        out: Any = buf
        if self.pool is not None:
            provider, policy = self.pool
            t0 = time.perf_counter()
            try:
                out = provider.alloc(len(buf), policy)
            except Exception:  # noqa: BLE001 - pool exhausted: put plainly, counted
                self.fallbacks += 1
                out = buf
            else:
                out[0 : len(buf)] = buf
                self.write_ms.append((time.perf_counter() - t0) * 1e3)
        out[off : off + 8] = struct.pack(">Q", time.time_ns())
        self.pub.put(out)
        if out is buf:
            self.plain_puts += 1
        else:
            self.shm_puts += 1

    def shm_stats(self) -> dict[str, Any]:
        """The camera's puts from its pool / plain / pool fallbacks, and the p50 of its write into the pool."""
        return {
            "shm_puts": self.shm_puts,
            "plain_puts": self.plain_puts,
            "fallbacks": self.fallbacks,
            "write_ms_p50": _pct(self.write_ms, 50),
        }

    def clear(self) -> None:
        """Forget the results so far."""
        self.latency.clear()
        self.stages.clear()
        self.write_ms.clear()

    def close(self) -> None:
        """Undeclare the subscriber and the publisher."""
        self.sub.undeclare()
        self.pub.undeclare()


def _camera_pool(pool_mb: int) -> tuple[zenoh.shm.ShmProvider, zenoh.shm.GarbageCollect] | None:
    """The camera's own shared-memory pool (None: ``--shm-pool-mb 0`` or no shared memory here)."""
    if not pool_mb:
        return None
    try:
        import zenoh.shm as zshm

        return zshm.ShmProvider.default_backend(pool_mb << 20), zshm.GarbageCollect()
    except Exception as exc:  # noqa: BLE001 - no SHM in this build / platform: plain puts
        print(f"camera: no shared memory ({exc}); plain puts", file=sys.stderr)
        return None


def _wait_until_up(camera: _Camera, proc: subprocess.Popen[bytes], log_path: Path, warmup: int) -> None:
    """Wait for the service's ``@status`` and ``warmup`` results (the routes are up), then drain."""
    deadline = time.monotonic() + 60
    while camera.query_status(1.0) is None:
        if proc.poll() is not None or time.monotonic() > deadline:
            raise RuntimeError(f"service did not come up:\n{log_path.read_text()[-3000:]}")
        time.sleep(0.2)
    w = 0
    while w < warmup:
        camera.send(w)
        if camera.got.acquire(timeout=5.0):
            w += 1
        elif proc.poll() is not None or time.monotonic() > deadline:
            raise RuntimeError(f"service not replying:\n{log_path.read_text()[-3000:]}")
    time.sleep(0.3)
    while camera.got.acquire(timeout=0.2):
        pass
    camera.clear()


def _run_client(
    a: argparse.Namespace,
    endpoint: str,
    payloads: list[tuple[bytearray, int]],
    *,
    painted: list[tuple[np.ndarray, np.ndarray]],
    matcher: Matcher,
    proc: subprocess.Popen[bytes],
    log_path: Path,
) -> _Runs:
    """Camera and result subscriber in this process: warm-up, (b) paced run beside the matcher alone, (c) unpaced."""
    import zenoh

    cc = zenoh.Config()
    cc.insert_json5("connect/endpoints", json.dumps([endpoint]))
    cc.insert_json5("scouting/multicast/enabled", "false")
    with zenoh.open(cc) as cli:
        camera = _Camera(cli, payloads, a.shm_pool_mb)
        _wait_until_up(camera, proc, log_path, a.warmup)

        # (b) paced: one frame in flight at --rate Hz; the matcher alone runs on the same
        # pair right after each result (the service idle), so both see the same background load
        period = 1.0 / a.rate
        m_ms = []
        for i in range(a.frames):
            t0 = time.perf_counter()
            camera.send(i)
            if not camera.got.acquire(timeout=10):
                raise RuntimeError(f"paced frame {i} lost:\n{log_path.read_text()[-3000:]}")
            left, right = painted[i % len(painted)]
            t1 = time.perf_counter()
            matcher.compute(left, right)
            m_ms.append((time.perf_counter() - t1) * 1e3)
            time.sleep(max(0.0, period - (time.perf_counter() - t0)))
        paced, paced_stages = list(camera.latency), list(camera.stages)
        camera_shm = camera.shm_stats()  # the paced run's writes into the camera's pool
        st_paced = camera.query_status() or {}

        # (c) throughput: as fast as possible, lossless queues
        camera.clear()
        t0 = time.perf_counter()
        for i in range(a.frames):
            camera.send(i)
        t_first = 0.0
        for k in range(a.frames):
            if not camera.got.acquire(timeout=30):
                break
            if k == 0:
                t_first = camera.t_last
        fps = len(camera.latency) / (camera.t_last - t0)
        # steady state: results 2..N over the time since the first (no pipeline fill)
        fps_steady = (len(camera.latency) - 1) / (camera.t_last - t_first) if len(camera.latency) > 1 else 0.0
        thr_lat = list(camera.latency)
        st_thr = camera.query_status() or {}
        camera.close()
    return _Runs(paced, paced_stages, m_ms, thr_lat, fps, fps_steady, st_paced, st_thr, camera_shm)


def _results(a: argparse.Namespace, runs: _Runs, m_before: list[float]) -> dict[str, Any]:
    """The JSON report: latencies, throughput, per-stage p50s and the overheads against the matcher alone."""
    paced, paced_stages, m_ms, st_paced = runs.paced, runs.paced_stages, runs.matcher_ms, runs.status_paced
    m_p50 = _pct(m_ms, 50)

    def stage_p50(key: str) -> float:
        return _pct([r[key] for r in paced_stages if key in r], 50)

    e2e_p50, e2e_p99 = _pct(paced, 50), _pct(paced, 99)
    thr_match_mean = float(runs.status_throughput.get("timing_ms", {}).get("match", {}).get("mean", float("nan")))
    # paired per frame: e2e minus the service's own match time (robust to load drift)
    per_frame = list(zip(paced, paced_stages, strict=True))  # one latency and one timing dict per result
    paired = [lt - st["match"] for lt, st in per_frame if "match" in st]
    dec, vpp, match = stage_p50("decode"), stage_p50("vpp"), stage_p50("match")
    sink_t = (st_paced.get("sinks", {}).get("ZenohSink", {}) or {}).get("timing_ms", {})
    enc, put = sink_t.get("encode", float("nan")), sink_t.get("put", float("nan"))
    # per frame, then p50: robust to the matcher's own drift (which a difference of p50s is not)
    frames = [(lt, st) for lt, st in per_frame if {"decode", "vpp", "match", "process"} <= st.keys()]
    # depth/metrics/conversions inside the process step
    other = _pct([st["process"] - st["vpp"] - st["match"] for _, st in frames], 50)
    # Zenoh both ways, queue hand-offs, the client: what is left of each frame's e2e
    transport = _pct([lt - st["decode"] - st["process"] - enc - put for lt, st in frames], 50)
    return {
        "size": [a.width, a.height],
        "frames": a.frames,
        "rate_hz": a.rate,
        "matcher": "sgbm",
        "max_disparity": a.max_disparity,
        "service": "separate process, loopback Zenoh tcp",
        "matcher_alone_ms": {
            "p50": m_p50,
            "p99": _pct(m_ms, 99),
            "mean": float(np.mean(m_ms)),
            "fps": 1e3 / float(np.mean(m_ms)),
        },
        "matcher_alone_before_service_ms": {"p50": _pct(m_before, 50), "p99": _pct(m_before, 99)},
        "e2e_minus_in_service_match_ms": {"p50": _pct(paired, 50), "p99": _pct(paired, 99)},
        "paired_overhead_pct_vs_in_service_match": 100.0 * _pct(paired, 50) / match,
        "service_e2e_ms": {"p50": e2e_p50, "p99": e2e_p99, "mean": float(np.mean(paced))},
        "service_fps": runs.fps,
        "service_fps_steady": runs.fps_steady,
        "overhead_pct": 100.0 * _pct(paired, 50) / m_p50,
        "throughput_ratio": runs.fps_steady * float(np.mean(m_ms)) / 1e3,
        # the same run's own match time: the share of the wall time the service spends matching (load-robust)
        "matcher_busy_ratio": runs.fps_steady * thr_match_mean / 1e3,
        "throughput_latency_ms": {"p50": _pct(runs.throughput_latency, 50), "p99": _pct(runs.throughput_latency, 99)},
        "breakdown_ms_p50": {
            "decode": dec,
            "vpp": vpp,
            "match_in_service": match,
            "process_other": other,
            "encode": enc,
            "put": put,
            "transport": transport,
        },
        "overhead_pct_vs_matcher": 100.0 * (e2e_p50 - m_p50) / m_p50,
        "paired_overhead_pct_vs_matcher_alone": 100.0 * _pct(paired, 50) / m_p50,
        "overhead_breakdown_pct_vs_matcher": 100.0 * (vpp + dec + enc + put + transport + other) / m_p50,
        "status_timing_ms_paced": {k: v["p50"] for k, v in st_paced.get("timing_ms", {}).items()},
        "status_timing_ms_throughput": {k: v["p50"] for k, v in runs.status_throughput.get("timing_ms", {}).items()},
        "counters": runs.status_throughput.get("counters", {}),
        "shm_pool_mb": a.shm_pool_mb,
        "camera_shm": runs.camera_shm,
    }


def _print_results(a: argparse.Namespace, results: dict[str, Any]) -> None:
    """The table of the results (from the report, so the printout and the JSON agree)."""
    m = results["matcher_alone_ms"]
    e2e, thr = results["service_e2e_ms"], results["throughput_latency_ms"]
    paired = results["e2e_minus_in_service_match_ms"]["p50"]
    match = results["breakdown_ms_p50"]["match_in_service"]
    print(
        f"SGBM, {a.width}x{a.height}, {a.max_disparity} disparities, {a.frames} frames; "
        f"service in its own process over tcp/127.0.0.1"
    )
    print(f"{'':34s}{'p50 ms':>9s}{'p99 ms':>9s}{'fps':>8s}")
    print(f"{'matcher alone (SGBM)':34s}{m['p50']:9.1f}{m['p99']:9.1f}{m['fps']:8.1f}")
    print(f"{f'service e2e, paced {a.rate:g} Hz':34s}{e2e['p50']:9.1f}{e2e['p99']:9.1f}{'':8s}")
    print(f"{'service unpaced (block queues)':34s}{thr['p50']:9.1f}{thr['p99']:9.1f}{results['service_fps']:8.1f}")
    print(f"{'  steady (results 2..N)':34s}{'':9s}{'':9s}{results['service_fps_steady']:8.1f}")
    print("breakdown of the paced e2e p50 (service stages from out/disparity timing_ms and @status):")
    for k, v in results["breakdown_ms_p50"].items():
        pct = 100.0 * v / m["p50"]
        print(f"  {k:32s}{v:9.2f} ms {pct:6.1f} % of matcher")
    print(
        f"overhead per frame, p50 of (e2e - in-service match): {paired:.2f} ms = "
        f"{results['paired_overhead_pct_vs_matcher_alone']:.1f} % of the matcher alone "
        f"(p50 {m['p50']:.1f} ms; {results['paired_overhead_pct_vs_in_service_match']:.1f} % of the "
        f"in-service match, p50 {match:.1f} ms)"
    )
    print(
        f"sum of the per-stage p50s above (vpp+decode+encode+put+other+transport): "
        f"{results['overhead_breakdown_pct_vs_matcher']:.1f} % of the matcher alone"
    )
    print(
        f"unpaired, (e2e p50 - matcher p50) / matcher p50: {results['overhead_pct_vs_matcher']:.1f} % "
        f"(matcher alone before the service started: p50 {results['matcher_alone_before_service_ms']['p50']:.1f} ms)"
    )
    cam = results["camera_shm"]
    print(
        f"camera (not in the e2e): wrote each frame into its pool in {cam.get('write_ms_p50', float('nan')):.2f} ms "
        f"(p50); puts from its pool {cam.get('shm_puts', 0)}, plain {cam.get('plain_puts', 0)}, "
        f"pool fallbacks {cam.get('fallbacks', 0)}"
    )
    print(
        f"HEADLINE overhead {results['overhead_pct']:.2f} % of the matcher (target <= 5), "
        f"throughput {results['throughput_ratio']:.3f} x the matcher's (target >= 0.95; "
        f"busy matching {results['matcher_busy_ratio']:.3f} of the unpaced run)"
    )


def _spread(runs: list[dict[str, Any]]) -> dict[str, dict[str, float]]:
    """Median, min and max over the runs of the headline numbers."""
    keys = ("overhead_pct", "throughput_ratio", "matcher_busy_ratio", "service_fps_steady")
    out = {k: [float(r[k]) for r in runs] for k in keys}
    out["matcher_alone_p50_ms"] = [float(r["matcher_alone_ms"]["p50"]) for r in runs]
    return {k: {"median": float(np.median(v)), "min": min(v), "max": max(v)} for k, v in out.items()}


def main(argv: Sequence[str] | None = None) -> int:
    """Run the benchmark (``--help`` for the options); print the table and write the JSON report."""
    a = _parse_args(argv)
    if a.runs < 1:
        raise SystemExit("--runs must be >= 1")
    from vpp_service.threads import configure_openmp

    configure_openmp()  # the camera side measures as the service runs; before the kernels load
    from vpp_service.fusion import fuse
    from vpp_service.matchers import build_matcher
    from vpp_service.service.config import validate_config
    from vpp_service.sources.sensors import build_sensor
    from vpp_service.sources.synthetic import make_scene

    n_unique = min(a.frames, 8)
    scene = make_scene(height=a.height, width=a.width, seed=0, max_disparity=96)
    sensor = build_sensor("uniform", {"density": 0.05})
    frames = [sensor.simulate(scene.with_(seq=i, rig=RIG), i) for i in range(n_unique)]  # the served rig
    tmp = Path(tempfile.mkdtemp(prefix="bench_service_"))
    ep = f"tcp/127.0.0.1:{_port()}"
    raw_cfg: dict[str, Any] = {
        "service": {"rig": RIG, "out": str(tmp / "out"), "summary": False, "timing_window": a.frames, "seed": 0},
        "zenoh": {"listen": [ep], "multicast_scouting": False},
        "source": {"type": "zenoh", "ring_size": 64, "poll_s": a.source_poll_s},
        "matcher": {"name": "sgbm", "max_disparity": a.max_disparity},
        "queues": {"input_size": 64, "input_policy": "block", "output_size": 64, "output_policy": "block"},
        "sinks": [{"type": "zenoh", "outputs": ["disparity"], "queue_size": 64, "shm_pool_mb": a.shm_pool_mb}],
    }
    cfg = validate_config(raw_cfg)
    payloads = _payloads(frames)

    # (a) matcher alone, on the very pairs the service matches (its fusion step with its seeds)
    matcher = build_matcher("sgbm", {"max_disparity": a.max_disparity})
    painted = []
    for f in frames:
        r = fuse(f, matcher, cfg.vpp, seed=cfg.service.seed + int(f.seq), depth=False)
        painted.append((f.left, f.right) if r.left_vpp is None or r.right_vpp is None else (r.left_vpp, r.right_vpp))
    for left, right in painted[:2]:
        matcher.compute(left, right)
    m_before = []
    for i in range(a.frames):
        left, right = painted[i % n_unique]
        t0 = time.perf_counter()
        matcher.compute(left, right)
        m_before.append((time.perf_counter() - t0) * 1e3)

    every: list[dict[str, Any]] = []
    for k in range(a.runs):
        # the service, as its own process, on a fresh port each run
        if k:
            ep = f"tcp/127.0.0.1:{_port()}"
            raw_cfg["zenoh"]["listen"] = [ep]
        proc, log_path = _start_service(raw_cfg, tmp, a)
        try:
            runs = _run_client(a, ep, payloads, painted=painted, matcher=matcher, proc=proc, log_path=log_path)
        finally:
            _stop_service(proc)
        if a.runs > 1:
            print(f"--- run {k + 1} of {a.runs}")
        results = _results(a, runs, m_before)
        _print_results(a, results)
        every.append(results)
    report: dict[str, Any] = every[0] if a.runs == 1 else {"runs": every, "spread": _spread(every)}
    if a.runs > 1:
        print(f"over {a.runs} runs (median [min, max]):")
        for key, v in report["spread"].items():
            print(f"  {key:24s}{v['median']:9.3f}  [{v['min']:.3f}, {v['max']:.3f}]")
    out = output_path(a, "bench_service")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(report, indent=2))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
