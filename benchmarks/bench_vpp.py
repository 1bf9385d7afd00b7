"""Benchmark of vpp_service.vpp.project against the cost of copying the two images.

Prints a table (median and minimum milliseconds) and writes JSON.  "x copy"
is the median time over the median copy time, "x (min)" the fastest run over
the fastest copy (the cost with the least interference from the rest of a
shared machine, whose second core is sometimes busy for a whole block of
runs); "paired" is the median of per-run ratios with a copy right before each
run (robust to slow drift).  Sizes: KITTI 1242x375,
Middlebury half 1482x994 and full 2964x1988 (RGB); densities 1 % and 5 %;
patterns random (vi) and histogram (vii), default 3x3 / alpha 0.4 / FGD;
threads 1 and all.  ``--quick`` runs a smaller subset.

Memory: by default freed memory is kept for reuse
(:func:`vpp_service.service.allocator.reuse_freed_memory`, as the service
does), so neither the copy nor VPP pays first-touch page faults for its
outputs.  Without it glibc sometimes maps a copy's 2 x 17.7 MB afresh and
sometimes not, and the copy reference swings between about 2.5 and 7 ms from
one process to the next; with it the copy is at its fastest, the strictest
reference.  ``--fresh-memory`` measures without it.
"""
from __future__ import annotations

import argparse
import json
import os

import numpy as np
from _harness import add_output_args, output_path, paired_ratio, times_ms

from vpp_service.service.allocator import reuse_freed_memory
from vpp_service.vpp import VPPConfig, project

SIZES = {"kitti": (375, 1242), "midd_half": (994, 1482), "midd_full": (1988, 2964)}


def scene(H: int, W: int, density: float, seed: int = 0):
    rng = np.random.default_rng(seed)
    small = rng.integers(0, 256, (H // 8 + 1, W // 8 + 1, 3), dtype=np.uint8)
    left = np.ascontiguousarray(np.repeat(np.repeat(small, 8, 0), 8, 1)[:H, :W])
    left = np.clip(left.astype(np.int16) + rng.integers(-8, 9, left.shape), 0, 255).astype(np.uint8)
    right = np.ascontiguousarray(np.roll(left, -20, axis=1))
    gt = (20 + 60 * np.sin(np.arange(W) / 150.0)[None, :] + np.arange(H)[:, None] / 20.0)
    disp = np.where(rng.random((H, W)) < density, gt, 0).astype(np.float32)
    return left, right, disp


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    add_output_args(ap, "bench_vpp")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--reps", type=int, default=15)
    ap.add_argument("--fresh-memory", action="store_true",
                    help="do not keep freed memory for reuse (outputs may be mapped afresh)")
    a = ap.parse_args(argv)
    memory = "fresh"
    if not a.fresh_memory and reuse_freed_memory():
        memory = "reused"
    print(f"memory: {memory}")
    allt = os.cpu_count() or 1
    sizes = ["kitti", "midd_half"] if a.quick else list(SIZES)
    dens = [0.05] if a.quick else [0.01, 0.05]
    threads = sorted({1, allt})
    rows = []
    print(f"{'size':10s} {'dens':>5s} {'pattern':10s} {'thr':>3s} {'ms':>8s} {'min ms':>8s} {'x copy':>7s} "
          f"{'x (min)':>7s} {'paired':>7s} {'points':>8s}")
    for name in sizes:
        H, W = SIZES[name]
        for density in dens:
            left, right, disp = scene(H, W, density)
            def copy():
                return left.copy(), right.copy()

            ct = times_ms(copy, a.reps)
            copy_ms, copy_min = float(np.median(ct)), float(ct.min())
            rows.append(dict(size=name, H=H, W=W, density=density, pattern="copy", threads=1,
                             ms=copy_ms, min_ms=copy_min, ratio=1.0, min_ratio=1.0))
            print(f"{name:10s} {density:5.2f} {'copy':10s} {1:3d} {copy_ms:8.2f} {copy_min:8.2f} {1.0:7.2f} "
                  f"{1.0:7.2f}")
            for pattern in ("random", "histogram"):
                cfg = VPPConfig(pattern=pattern)
                for nt in threads:
                    def run():
                        return project(left, right, disp, cfg, num_threads=nt)

                    t = times_ms(run, a.reps)
                    ms, mn = float(np.median(t)), float(t.min())
                    paired = paired_ratio(run, copy, a.reps)
                    npts = project(left, right, disp, cfg).stats.given
                    rows.append(dict(size=name, H=H, W=W, density=density, pattern=pattern,
                                     threads=nt, ms=ms, min_ms=mn, ratio=ms / copy_ms,
                                     min_ratio=mn / copy_min, paired_ratio=paired, points=npts))
                    print(f"{name:10s} {density:5.2f} {pattern:10s} {nt:3d} {ms:8.2f} {mn:8.2f} "
                          f"{ms / copy_ms:7.2f} {mn / copy_min:7.2f} {paired:7.2f} {npts:8d}")
    out = output_path(a, "bench_vpp")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"cpu_count": allt, "memory": memory, "results": rows}, indent=1))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
