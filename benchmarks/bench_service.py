"""Service benchmark: frames/s and end-to-end latency over loopback Zenoh vs the matcher alone.

At KITTI size (1242 x 375, a synthetic scene with exact ground truth and a
uniform 5 % sensor) it measures

1. the matcher alone on the raw pair (the floor);
2. the whole service path: encode -> Zenoh (tcp/127.0.0.1) -> decode -> VPP ->
   SGBM -> encode -> Zenoh -> decode, at a paced rate (latency, no queueing) and
   as fast as possible with lossless queues (throughput).

The service runs in this process (its own threads and Zenoh session), the
camera and the client in separate sessions. Overhead = (e2e p50 - matcher p50)
/ matcher p50. Prints a table, writes JSON (``--json``).

    python benchmarks/bench_service.py --frames 30 --json bench_service.json
"""
from __future__ import annotations

import argparse
import json
import socket
import threading
import time

import numpy as np


def _port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def main() -> int:
    import zenoh

    from vpp_service.matchers import build_matcher
    from vpp_service.service import wire
    from vpp_service.service.app import build_pipeline, open_session
    from vpp_service.service.config import validate_config
    from vpp_service.sources.sensors import build_sensor
    from vpp_service.sources.synthetic import make_scene

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=30)
    ap.add_argument("--width", type=int, default=1242)
    ap.add_argument("--height", type=int, default=375)
    ap.add_argument("--max-disparity", type=int, default=128)
    ap.add_argument("--json", default="bench_service.json")
    a = ap.parse_args()

    scene = make_scene(height=a.height, width=a.width, seed=0, max_disparity=96)
    sensor = build_sensor("uniform", {"density": 0.05})
    frames = [sensor.simulate(scene.with_(seq=i), i) for i in range(a.frames)]
    payloads = [wire.encode_frame(f, include_gt=False) for f in frames]

    matcher = build_matcher("sgbm", {"max_disparity": a.max_disparity})
    matcher.compute(scene.left, scene.right)
    m_ms = []
    for f in frames:
        t0 = time.perf_counter()
        matcher.compute(f.left, f.right)
        m_ms.append((time.perf_counter() - t0) * 1e3)
    m_p50 = float(np.percentile(m_ms, 50))

    port = _port()
    ep = f"tcp/127.0.0.1:{port}"
    cfg = validate_config({
        "service": {"rig": "bench", "out": "out/bench", "summary": False},
        "zenoh": {"listen": [ep]},
        "source": {"type": "zenoh", "ring_size": 64},
        "matcher": {"name": "sgbm", "max_disparity": a.max_disparity},
        "queues": {"input_size": 64, "input_policy": "block", "output_size": 64, "output_policy": "block"},
        "sinks": [{"type": "zenoh", "outputs": ["disparity"], "queue_size": 64}],
    })
    results = {}
    with open_session(cfg.zenoh) as svc_session:
        pipe = build_pipeline(cfg, svc_session)
        pipe.start()
        cc = zenoh.Config()
        cc.insert_json5("connect/endpoints", json.dumps([ep]))
        cc.insert_json5("scouting/multicast/enabled", "false")
        with zenoh.open(cc) as cli:
            lat: list[float] = []
            got = threading.Semaphore(0)

            def on_out(sample: zenoh.Sample) -> None:
                msg = wire.unpack(sample.payload.to_bytes())
                lat.append((time.time_ns() - msg["stamp_ns"]) / 1e6)
                got.release()

            sub = cli.declare_subscriber("vpp/bench/out/disparity", on_out)
            pub = cli.declare_publisher("vpp/bench/in/frame", congestion_control=zenoh.CongestionControl.BLOCK)
            time.sleep(0.5)

            def send(i: int) -> None:
                import msgpack

                msg = msgpack.unpackb(payloads[i % len(payloads)], raw=False)
                msg["stamp_ns"], msg["seq"] = time.time_ns(), i
                pub.put(msgpack.packb(msg, use_bin_type=True))

            # paced: one frame at a time (latency without queueing)
            for i in range(a.frames):
                send(i)
                got.acquire(timeout=10)
            paced = list(lat)
            # throughput: as fast as possible, lossless queues
            lat.clear()
            t0 = time.perf_counter()
            for i in range(a.frames):
                send(a.frames + i)
            for _ in range(a.frames):
                got.acquire(timeout=30)
            fps = len(lat) / (time.perf_counter() - t0)
            sub.undeclare()
        status = pipe.status()
        pipe.stop(5.0)
    p50, p99 = float(np.percentile(paced, 50)), float(np.percentile(paced, 99))
    t = status["timing_ms"]
    results = {
        "size": [a.width, a.height], "frames": a.frames, "matcher": "sgbm", "max_disparity": a.max_disparity,
        "matcher_alone_ms": {"p50": m_p50, "mean": float(np.mean(m_ms)), "fps": 1e3 / float(np.mean(m_ms))},
        "service_e2e_ms": {"p50": p50, "p99": p99, "mean": float(np.mean(paced))},
        "service_fps": fps,
        "service_stage_ms": {k: v["p50"] for k, v in t.items()},
        "overhead_pct_vs_matcher": 100.0 * (p50 - m_p50) / m_p50,
        "vpp_pct_vs_matcher": 100.0 * t.get("vpp", {}).get("p50", 0.0) / m_p50,
        # service-side work besides matching (decode + VPP + conversions), vs the matcher in the same run
        "stage_overhead_pct": 100.0 * (t["decode"]["p50"] + t["process"]["p50"] - t["match"]["p50"])
        / t["match"]["p50"],
        "counters": status["counters"],
    }
    print(f"{'':32s}{'p50 ms':>10s}{'p99 ms':>10s}{'fps':>8s}")
    print(f"{'matcher alone (SGBM)':32s}{m_p50:10.1f}{np.percentile(m_ms, 99):10.1f}{1e3 / np.mean(m_ms):8.1f}")
    print(f"{'service e2e (paced)':32s}{p50:10.1f}{p99:10.1f}{'':8s}")
    print(f"{'service throughput':32s}{'':10s}{'':10s}{fps:8.1f}")
    for k, v in results["service_stage_ms"].items():
        print(f"  stage {k:24s}{v:10.1f}")
    print(f"VPP + transport overhead vs matcher: {results['overhead_pct_vs_matcher']:.1f} % "
          f"(VPP alone {results['vpp_pct_vs_matcher']:.1f} %; decode+VPP+conversions vs in-service "
          f"matcher {results['stage_overhead_pct']:.1f} %)")
    with open(a.json, "w") as fh:
        json.dump(results, fh, indent=2)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
