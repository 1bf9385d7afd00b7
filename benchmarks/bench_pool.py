"""Worker pool on loopback: throughput scaling, failover after a SIGKILL, steady state.

A Zenoh router (a subprocess), N workers (``python -m vpp_service run --pool``,
client mode, Zenoh source, zenoh sink, each ``OMP_NUM_THREADS=1`` with the
1-thread ``census-sgm`` matcher), and this process: a camera publishing
simulated frames (raw images, ``CongestionControl.BLOCK``, its own ``seq``) and
a subscriber on ``out/disparity`` noting when each answer came and from whom.

(a) Scaling, ``--rounds`` rounds over N = 1..``--max-workers`` (interleaved, so
drift of the shared machine hits every N alike): ``--frames`` frames offered
as fast as the pool takes them (back-pressure through the workers' blocking
input); throughput = answers per second between the ``--warmup``-th and the
last answer. Reported per N: median, min, max, and the speedup over one worker
(median of the per-round ratios). The issue's target: 2 workers >= 1.7x one.
Also per N: the CPU the workers got (cores, from ``/proc``), how busy the
whole machine was, and frames per worker core-second with its ratio to one
worker's (``efficiency``): on a machine shared with other work the speedup is
bounded by the cores the pool is lent; the efficiency is the pool's own cost.

(b) Failover, ``--kills`` times: two workers, frames at ``--kill-rate`` Hz; a
burst of ``--burst`` frames gives the victim a backlog, then it is SIGKILLed
and the stream goes on. Reported: kill -> token loss seen by this process;
frames taken over and lost (the survivor's counters) vs frames never
answered; ``failover_ms``, from the token loss to the survivor's first answer
of a frame of the victim's share; for frames published after the loss, whether
all were answered and their largest latency (publish -> answer; the survivor
also works off the backlog it took over). Target: the survivor serves new
frames within 1 s of the token loss.

(c) Steady state: two workers (small SGBM, quarter scale), ``--steady``
frames at ``--steady-rate`` Hz: duplicates and gaps among the answers (and the
pool's own counters). Target: 0 and 0 over 1,000 frames.

Prints tables and writes JSON (default ``out/benchmarks/bench_pool.json``).

    python benchmarks/bench_pool.py
    python benchmarks/bench_pool.py --rounds 1 --frames 40 --kills 1 --steady 200   # quick look
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import threading
import time
from collections import Counter
from pathlib import Path

from _harness import add_output_args, output_path, write_report

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))  # the router process and the worker configs are shared with the tests

import msgpack  # noqa: E402
import zenoh  # noqa: E402

from helpers.pool import start_worker, stop_all, wait_members, worker_config  # noqa: E402
from helpers.zenoh_loopback import free_port, zenoh_test_config  # noqa: E402
from helpers.zenoh_router import RouterProcess  # noqa: E402
from vpp_service.frame import StereoFrame  # noqa: E402
from vpp_service.service.pool import owner  # noqa: E402
from vpp_service.sources.sensors import UniformSensor  # noqa: E402
from vpp_service.sources.sim import motorcycle_frame  # noqa: E402
from vpp_service.transport import wire  # noqa: E402

ONE_THREAD = {"OMP_NUM_THREADS": "1"}
CENSUS = 'name = "census-sgm"\nmax_disparity = 128\nthreads = 1'
SGBM = 'name = "sgbm"\nmax_disparity = 48'


class Answers:
    """``out/disparity`` of one rig: (arrival time, seq, worker) of every answer."""

    def __init__(self, session: zenoh.Session, rig: str) -> None:
        self.rows: list[tuple[float, int, str]] = []
        self._lock = threading.Lock()
        self._sub = session.declare_subscriber(f"vpp/{rig}/out/disparity", self._on)

    def _on(self, sample: zenoh.Sample) -> None:
        msg = msgpack.unpackb(sample.payload.to_bytes())  # the header is all this needs (cheap on a busy machine)
        with self._lock:
            self.rows.append((time.monotonic(), int(msg["seq"]), str(msg.get("worker", "?"))))

    def snapshot(self) -> list[tuple[float, int, str]]:
        """The answers so far."""
        with self._lock:
            return list(self.rows)

    def wait(self, n: int, timeout: float) -> list[tuple[float, int, str]]:
        """The answers once there are ``n`` (or ``timeout`` passed)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline and len(self.snapshot()) < n:
            time.sleep(0.02)
        return self.snapshot()

    def close(self) -> None:
        """Stop listening."""
        self._sub.undeclare()


class Camera:
    """Publishes frames of ``rig`` with consecutive ``seq`` values (raw images, BLOCK)."""

    def __init__(self, session: zenoh.Session, rig: str, scale: float) -> None:
        base = UniformSensor(UniformSensor.Options(density=0.05)).simulate(motorcycle_frame(scale))
        self.frame: StereoFrame = base.with_(rig=rig)
        self.pub = session.declare_publisher(f"vpp/{rig}/in/frame", congestion_control=zenoh.CongestionControl.BLOCK)
        self.seq = 0
        self.sent: dict[int, float] = {}

    def encode(self, n: int) -> list[bytes]:
        """The next ``n`` frames' messages (no ground truth: the workers only match)."""
        return [
            wire.encode_frame(self.frame.with_(seq=self.seq + i, stamp_ns=time.time_ns()), "raw", include_gt=False)
            for i in range(n)
        ]

    def send(self, n: int, rate: float = 0.0, encoded: list[bytes] | None = None) -> None:
        """Publish ``n`` frames (``rate`` per second; 0 = as fast as they are taken), pre-encoded or not."""
        period = 1.0 / rate if rate > 0 else 0.0
        t0 = time.monotonic()
        for i in range(n):
            if period:
                time.sleep(max(0.0, t0 + i * period - time.monotonic()))
            payload = encoded[i] if encoded is not None else self.encode(1)[0]
            self.sent[self.seq] = time.monotonic()
            self.pub.put(payload)
            self.seq += 1


class Pool:
    """A router and ``n`` workers of one rig, with this process's session (client of the router)."""

    def __init__(self, folder: Path, n: int, rig: str, matcher: str, deadline_ms: float = 1000.0) -> None:
        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        self.rig = rig
        self.ids = [f"w{i}" for i in range(n)]
        self.router = RouterProcess(self.endpoint)
        self.router.start()
        cfgs = [
            worker_config(folder, self.endpoint, rig, w, matcher=matcher, deadline_ms=deadline_ms, input_size=8)
            for w in self.ids
        ]
        self.procs = [start_worker(c, folder / f"{w}.log", ONE_THREAD) for c, w in zip(cfgs, self.ids, strict=True)]
        self.session = zenoh.open(zenoh_test_config(connect=[self.endpoint], mode="client"))
        wait_members(self.session, rig, n, self.procs, timeout=60)

    def status(self) -> dict[str, dict[str, object]]:
        """Each worker's ``@status``, by worker id."""
        out = {}
        for r in self.session.get(f"vpp/{self.rig}/@status/**", timeout=3.0):
            if r.ok is not None:
                st = json.loads(r.ok.payload.to_string())
                out[st["pool"]["worker"]] = st
        return out

    def close(self) -> None:
        """Stop the workers, the session and the router."""
        stop_all(self.procs)
        self.session.close()
        self.router.kill()


def cpu_s(pid: int) -> float:
    """CPU seconds (user + system) process ``pid`` has used so far (Linux ``/proc``)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def machine_busy() -> tuple[float, float]:
    """(busy, total) jiffies of every CPU so far (``/proc/stat``)."""
    vals = [int(v) for v in Path("/proc/stat").read_text().splitlines()[0].split()[1:]]
    idle = vals[3] + vals[4]
    return sum(vals) - idle, sum(vals)


def throughput(rows: list[tuple[float, int, str]], warmup: int) -> float:
    """Answers per second from the ``warmup``-th answer to the last."""
    ts = sorted(t for t, _, _ in rows)[warmup:]
    return (len(ts) - 1) / (ts[-1] - ts[0]) if len(ts) > 1 and ts[-1] > ts[0] else 0.0


def scaling(a: argparse.Namespace) -> list[dict[str, object]]:
    """(a): throughput per pool size, interleaved rounds."""
    per_n: dict[int, list[float]] = {n: [] for n in range(1, a.max_workers + 1)}
    cpu: dict[int, list[float]] = {n: [] for n in per_n}
    busy: dict[int, list[float]] = {n: [] for n in per_n}
    for r in range(a.rounds):
        for n, vals in per_n.items():
            with tempfile.TemporaryDirectory() as tmp:
                pool = Pool(Path(tmp), n, f"scale{n}r{r}", CENSUS)
                try:
                    answers = Answers(pool.session, pool.rig)
                    cam = Camera(pool.session, pool.rig, a.scale)
                    encoded = cam.encode(a.frames)
                    c0, m0, t0 = [cpu_s(p.pid) for p in pool.procs], machine_busy(), time.monotonic()
                    cam.send(a.frames, encoded=encoded)
                    rows = answers.wait(a.frames, timeout=a.frames * 2.0)
                    c1, m1, wall = [cpu_s(p.pid) for p in pool.procs], machine_busy(), time.monotonic() - t0
                    answers.close()
                finally:
                    pool.close()
            fps = throughput(rows, a.warmup)
            vals.append(fps)
            cpu[n].append(sum(b - a_ for a_, b in zip(c0, c1, strict=True)) / wall)  # cores the workers used
            busy[n].append((m1[0] - m0[0]) / max(1, m1[1] - m0[1]))
            print(
                f"  round {r + 1}: {n} worker(s): {len(rows)}/{a.frames} answers, {fps:.2f} frames/s, "
                f"workers used {cpu[n][-1]:.2f} cores, machine {100 * busy[n][-1]:.0f} % busy",
                flush=True,
            )
    one = per_n[1]
    out = []
    for n, vals in per_n.items():
        ratios = [v / o for v, o in zip(vals, one, strict=True) if o > 0]
        # frames per core-second the workers got: the pool's own cost, apart from what the machine lends it
        per_core = [v / c for v, c in zip(vals, cpu[n], strict=True) if c > 0]
        per_core_one = [v / c for v, c in zip(one, cpu[1], strict=True) if c > 0]
        out.append(
            {
                "workers": n,
                "fps_median": statistics.median(vals),
                "fps_min": min(vals),
                "fps_max": max(vals),
                "fps_rounds": vals,
                "speedup_median": statistics.median(ratios) if ratios else None,
                "speedup_rounds": ratios,
                "worker_cores_median": statistics.median(cpu[n]),
                "worker_cores_rounds": cpu[n],
                "fps_per_core_median": statistics.median(per_core) if per_core else None,
                "efficiency_median": (
                    statistics.median(per_core) / statistics.median(per_core_one) if per_core and per_core_one else None
                ),
                "machine_busy_median": statistics.median(busy[n]),
            }
        )
    return out


def failover(a: argparse.Namespace, k: int) -> dict[str, object]:
    """(b): one of two workers SIGKILLed mid-stream."""
    with tempfile.TemporaryDirectory() as tmp:
        pool = Pool(Path(tmp), 2, f"kill{k}", CENSUS, deadline_ms=a.deadline_ms)
        victim, survivor = pool.ids
        lost_at: list[float] = []

        def on_token(sample: zenoh.Sample) -> None:
            if sample.kind == zenoh.SampleKind.DELETE and str(sample.key_expr).endswith(f"/{victim}"):
                lost_at.append(time.monotonic())

        watch = pool.session.liveliness().declare_subscriber(f"vpp/{pool.rig}/@pool/*", on_token)
        try:
            answers = Answers(pool.session, pool.rig)
            cam = Camera(pool.session, pool.rig, a.scale)
            half = int(a.kill_rate * a.kill_s / 2)
            cam.send(half, a.kill_rate)
            cam.send(a.burst)  # the victim's share of it waits in its queue
            t_kill = time.monotonic()
            pool.procs[0].kill()
            pool.procs[0].wait()
            cam.send(half, a.kill_rate)
            time.sleep(3.0)  # the survivor works off what it took over
            rows = answers.snapshot()
            st = pool.status()[survivor]["pool"]
            answers.close()
        finally:
            watch.undeclare()
            pool.close()
    if not lost_at:
        return {"kill": k, "error": "the token loss was never seen"}
    t_loss = lost_at[0]
    answered = Counter(s for _, s, _ in rows)
    sent = cam.sent
    new = [s for s, t in sent.items() if t >= t_loss]
    first_victim = min(
        (t for t, s, w in rows if t >= t_loss and w == survivor and owner(s, pool.ids) == victim), default=None
    )
    answer_at = {s: t for t, s, _ in sorted(rows, reverse=True)}  # the first answer of each seq
    new_latency = [answer_at[s] - sent[s] for s in new if s in answer_at]
    missing = [s for s in sent if s not in answered]
    return {
        "kill": k,
        "detect_ms": (t_loss - t_kill) * 1e3,
        "lost": st["lost"],  # type: ignore[index]
        "taken_over": st["taken_over"],  # type: ignore[index]
        "unanswered": len(missing),
        "duplicates_seen": sum(c - 1 for c in answered.values()),
        "failover_ms": None if first_victim is None else (first_victim - t_loss) * 1e3,
        "new_frames": len(new),
        "new_unanswered": sum(1 for s in new if s not in answered),
        "new_latency_max_ms": max(new_latency) * 1e3 if new_latency else None,
    }


def steady(a: argparse.Namespace) -> dict[str, object]:
    """(c): duplicates and gaps over a long steady stream."""
    from vpp_service.transport.reorder import ReorderBuffer

    with tempfile.TemporaryDirectory() as tmp:
        pool = Pool(Path(tmp), 2, "steady", SGBM)
        try:
            answers = Answers(pool.session, pool.rig)
            cam = Camera(pool.session, pool.rig, 0.25)
            t0 = time.monotonic()
            cam.send(a.steady, a.steady_rate)
            rows = answers.wait(a.steady, timeout=60)
            time.sleep(1.0)  # a duplicate would come now
            rows = answers.snapshot()
            elapsed = time.monotonic() - t0
            st = pool.status()
            answers.close()
        finally:
            pool.close()
    seqs = Counter(s for _, s, _ in rows)
    order: ReorderBuffer[None] = ReorderBuffer(16, 0.5)
    for _, s, _ in rows:
        order.push(s, None)
    order.flush()
    ost = order.stats()
    return {
        "frames": a.steady,
        "answers": len(rows),
        "duplicates": sum(c - 1 for c in seqs.values()),
        "gaps": a.steady - len(seqs),
        "reorder": dict(ost),
        "pool_duplicates": sum(int(s["pool"]["duplicates"]) for s in st.values()),  # type: ignore[index]
        "pool_lost": sum(int(s["pool"]["lost"]) for s in st.values()),  # type: ignore[index]
        "shares": {w: int(s["pool"]["own"]) for w, s in st.items()},  # type: ignore[index]
        "seconds": elapsed,
    }


def main(argv: list[str] | None = None) -> int:
    """Run the parts asked for, print the tables, write the JSON."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rounds", type=int, default=3, help="scaling rounds over 1..max-workers")
    ap.add_argument("--max-workers", type=int, default=4)
    ap.add_argument("--frames", type=int, default=60, help="frames per scaling run")
    ap.add_argument("--warmup", type=int, default=5, help="answers before the throughput clock starts")
    ap.add_argument("--scale", type=float, default=0.5, help="simulated frame scale (census-sgm runs)")
    ap.add_argument("--kills", type=int, default=3, help="failover runs")
    ap.add_argument("--kill-rate", type=float, default=4.0, help="frames/s offered in the failover runs")
    ap.add_argument("--kill-s", type=float, default=8.0, help="seconds of frames per failover run")
    ap.add_argument("--burst", type=int, default=4, help="frames sent at once right before the kill")
    ap.add_argument("--deadline-ms", type=float, default=1000.0, help="pool_deadline_ms of the failover runs")
    ap.add_argument("--steady", type=int, default=1000, help="frames of the steady-state run (0 = skip)")
    ap.add_argument("--steady-rate", type=float, default=40.0)
    ap.add_argument("--skip", nargs="*", default=[], choices=["scaling", "failover", "steady"])
    add_output_args(ap, "bench_pool")
    a = ap.parse_args(argv)
    report: dict[str, object] = {}
    if "scaling" not in a.skip:
        print(f"(a) scaling: census-sgm 1 thread, scale {a.scale}, {a.frames} frames, {a.rounds} rounds", flush=True)
        rows = scaling(a)
        report["scaling"] = rows
        print(
            f"{'workers':>7} {'fps median':>10} {'min':>6} {'max':>6} {'speedup':>8} {'cores':>6} {'busy':>5} "
            f"{'fps/core':>8} {'effic.':>6}"
        )
        for r in rows:
            sp = r["speedup_median"]
            print(
                f"{r['workers']:>7} {r['fps_median']:>10.2f} {r['fps_min']:>6.2f} {r['fps_max']:>6.2f} "
                f"{sp if sp is None else f'{sp:.2f}x':>8} {r['worker_cores_median']:>6.2f} "
                f"{100 * r['machine_busy_median']:>4.0f}% {r['fps_per_core_median'] or 0:>8.2f} "
                f"{r['efficiency_median'] or 0:>6.2f}"
            )
    if "failover" not in a.skip:
        print(f"(b) failover: 2 workers, {a.kill_rate} frames/s, SIGKILL one mid-stream, {a.kills} runs", flush=True)
        kills = [failover(a, k) for k in range(a.kills)]
        report["failover"] = kills
        for r in kills:
            print("  " + ", ".join(f"{k} {v:.0f}" if isinstance(v, float) else f"{k} {v}" for k, v in r.items()))
    if "steady" not in a.skip and a.steady:
        print(f"(c) steady state: 2 workers, {a.steady} frames at {a.steady_rate} frames/s", flush=True)
        st = steady(a)
        report["steady"] = st
        print(f"  {st}")
    path = write_report(output_path(a, "bench_pool"), [report], cpu_count_note="2 cores shared with other work")
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
