"""Networks on Triton: throughput with 1 and 2 servers and ``in_flight`` 1/2/4/8, bytes and client cost per frame.

Starts real ``tritonserver`` processes (the nvidia-pytriton wheel's binary, in the
test helpers' cached venv, ``tests/helpers/triton_server.py``) hosting PSMNet in a
Python-backend model that runs the ``.onnx`` with ONNX Runtime, ``--threads``
intra-op threads per server, and streams ``--frames`` crops of the KITTI frame
through the ``psmnet`` matcher's ``triton`` engine in the service's in-flight
window (:class:`vpp_service.service.in_flight.InFlight`), back to back.

Per configuration: frames/s, the speed-up over one server at the same
``in_flight``, tensor bytes on the wire per frame (out + back), and the client's
own CPU time per frame (pre/post-processing, serialisation, gRPC).

    python benchmarks/bench_triton.py                      # PSMNet, 256 x 352 crops, 12 frames
    python benchmarks/bench_triton.py --tiny --frames 40   # the tiny SAD network (a quick check)

The JSON goes to ``out/benchmarks/bench_triton.json`` unless ``--json`` says otherwise.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from _harness import REPO, add_output_args, output_path, write_report

sys.path.insert(0, str(REPO / "tests"))

from helpers.triton_server import TritonServer, server_venv, write_model
from vpp_service.matchers import build_matcher
from vpp_service.matchers.onnx import OnnxMatcher
from vpp_service.service.in_flight import InFlight

SHARED = REPO.parent / "shared"


def pairs(n: int, size: tuple[int, int], tiny: bool) -> list[tuple[np.ndarray, np.ndarray]]:
    """``n`` stereo pairs: crops of the KITTI frame (shifted window per frame), or random texture for ``--tiny``."""
    h, w = size
    if tiny:
        rng = np.random.default_rng(0)
        out = []
        for _ in range(n):
            tex = rng.integers(0, 256, (h, w + 5, 3), dtype=np.uint8)
            out.append((np.ascontiguousarray(tex[:, :w]), np.ascontiguousarray(tex[:, 5:])))
        return out
    from vpp_service.datasets import open_dataset

    frame = open_dataset("auto", SHARED / "data" / "kitti2012_training", color=True)[0]
    width = frame.left.shape[1]
    out = []
    for i in range(n):
        x = (i * 61) % (width - w)
        out.append(
            (
                np.ascontiguousarray(frame.left[-h:, x : x + w]),
                np.ascontiguousarray(frame.right[-h:, x : x + w]),
            )
        )
    return out


def stream(matcher: OnnxMatcher, data: list[tuple[np.ndarray, np.ndarray]], in_flight: int) -> dict[str, float]:
    """Match ``data`` through an in-flight window; wall time, client CPU time, answers in order."""
    got: list[int] = []
    failed: list[str] = []
    window: InFlight[int, int] = InFlight(
        in_flight,
        lambda i: (matcher.compute(*data[i]), i)[1],
        got.append,
        lambda i, exc: failed.append(f"{i}: {exc}"),
        name="bench",
    )
    c0, t0 = time.process_time(), time.perf_counter()
    for i in range(len(data)):
        window.submit(i)
    window.close()
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    if failed or got != list(range(len(data))):
        raise RuntimeError(f"frames lost or out of order: {got} {failed}")
    return {"wall_s": wall, "cpu_s": cpu}


def main() -> int:
    """Start the servers, stream the frames for each configuration, print the table and write the JSON."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=12)
    ap.add_argument("--size", type=int, nargs=2, default=(256, 352), metavar=("H", "W"))
    ap.add_argument("--in-flight", type=int, nargs="+", default=[1, 2, 4, 8])
    ap.add_argument("--servers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--threads", type=int, default=1, help="ONNX Runtime intra-op threads per server")
    ap.add_argument("--tiny", action="store_true", help="the tiny SAD network instead of PSMNet")
    add_output_args(ap, "bench_triton")
    a = ap.parse_args()
    data = pairs(a.frames, tuple(a.size), a.tiny)
    work = Path(tempfile.mkdtemp(prefix="bench-triton-"))
    io = {"left": (1, 3, None, None), "right": (1, 3, None, None)}
    if a.tiny:
        sys.path.insert(0, str(REPO / "tests"))
        from helpers.tiny_networks import sad_stereo

        model = sad_stereo(work / "sad16.onnx", 16)
        name, card = "sad16", {"name": "sad16", "max_disparity": 16}
    else:
        model = SHARED / "models" / "psmnet_kitti2015.onnx"
        name, card = "psmnet_kitti2015", {}
    write_model(work / "repo", name, model, io, {"disparity": (1, None, None)}, threads=a.threads)
    venv = server_venv()
    servers = [TritonServer(venv, work / "repo", work / f"server{i}").start() for i in range(max(a.servers))]
    rows: list[dict[str, Any]] = []
    try:
        for n in sorted(a.servers):
            for k in a.in_flight:
                # a request's deadline covers its wait in the server's queue too: in_flight frames of seconds each
                opts = {
                    "engine": "triton",
                    "url": [s.url for s in servers[:n]],
                    "in_flight": k,
                    "model": name,
                    "timeout_ms": 3_600_000.0,
                }
                m = build_matcher("onnx" if a.tiny else "psmnet", {**opts, **({"card": card} if card else {})})
                assert isinstance(m, OnnxMatcher)
                m.compute(*data[0])  # warm-up: metadata, channels, the servers' first run
                before = dict(m.network_status() or {})
                r = stream(m, data, k)
                after = m.network_status() or {}
                frames = len(data)
                row = {
                    "servers": n,
                    "in_flight": k,
                    "frames": frames,
                    "fps": frames / r["wall_s"],
                    "wall_s": r["wall_s"],
                    "bytes_out_per_frame": (int(after["bytes_out"]) - int(before["bytes_out"])) / frames,
                    "bytes_in_per_frame": (int(after["bytes_in"]) - int(before["bytes_in"])) / frames,
                    "client_cpu_ms_per_frame": r["cpu_s"] * 1e3 / frames,
                    "retried": int(after["retried"]) - int(before["retried"]),
                }
                rows.append(row)
                print(f"  {n} server(s), in_flight {k}: {row['fps']:.3f} frames/s", flush=True)
    finally:
        for s in servers:
            s.stop()
    one = {r["in_flight"]: float(r["fps"]) for r in rows if r["servers"] == 1}
    for r in rows:
        base = one.get(r["in_flight"])
        r["speedup_vs_1_server"] = float(r["fps"]) / base if base else None
    head = ("servers", "in_flight", "frames/s", "speed-up", "MB out", "MB in", "client ms")
    print("\n" + " ".join(f"{h:>9}" for h in head))
    for r in rows:
        sp = r["speedup_vs_1_server"]
        cells = (
            str(r["servers"]),
            str(r["in_flight"]),
            f"{r['fps']:.3f}",
            "" if sp is None else f"{sp:.2f}x",
            f"{r['bytes_out_per_frame'] / 1e6:.2f}",
            f"{r['bytes_in_per_frame'] / 1e6:.2f}",
            f"{r['client_cpu_ms_per_frame']:.1f}",
        )
        print(" ".join(f"{c:>9}" for c in cells))
    path = output_path(a, "bench_triton")
    write_report(
        path,
        rows,
        model=name,
        size=list(a.size),
        threads_per_server=a.threads,
        server="tritonserver (nvidia-pytriton 0.7.0 wheel), Python backend running ONNX Runtime on CPU",
    )
    print(f"\nwrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
