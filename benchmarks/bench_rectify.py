"""Benchmark of rectification (``[rectify]``) against census-SGM's frame time at 720p.

Frames: a textured RGB pair (and its gray version) of 1280 x 720, D = 128. A camera_info
pair with plumb_bob ``k1 = -0.12`` and rotations under 1 degree. Timed, each the median
over ``--reps`` runs after one warm-up: the remap tables' construction (once per
calibration), the rectification of one frame (both views, the fixed-point maps the
service uses, :class:`vpp_service.rectify.StereoRectifier`), the same remap with float
maps (what the fixed-point form saves), and census-SGM (8 paths, all threads) on the
rectified pair. The table's last column is rectification / census-SGM; the issue's budget
is 15 %.

Prints a table and writes JSON (default ``out/benchmarks/bench_rectify.json``;
``--update-committed`` writes ``benchmarks/results/bench_rectify.json``).
"""

from __future__ import annotations

import argparse

import cv2
import numpy as np
from _harness import add_output_args, median_ms, output_path, write_report

from vpp_service.frame import StereoFrame
from vpp_service.matchers import build_matcher
from vpp_service.rectify import CameraInfo, StereoRectifier

W, H, D = 1280, 720, 128


def _cameras() -> tuple[CameraInfo, CameraInfo]:
    f, cx, cy = 900.0, (W - 1) / 2, (H - 1) / 2
    p_left = np.array([[f, 0, cx, 0], [0, f, cy, 0], [0, 0, 1, 0]])
    p_right = p_left.copy()
    p_right[0, 3] = -f * 0.12
    cams = []
    for p, rot, dk in ((p_left, (0.4, -0.6, 0.3), 6.0), (p_right, (-0.5, 0.7, -0.4), -4.0)):
        k = np.array([[f + dk, 0, cx + 3], [0, f + dk, cy - 2], [0, 0, 1]])
        r = cv2.Rodrigues(np.deg2rad(rot))[0]
        cams.append(CameraInfo(W, H, k, np.array([-0.12, 0.03, 0.0008, -0.0005, 0.0]), r, p))
    return cams[0], cams[1]


def _pair(channels: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(0)
    base = cv2.GaussianBlur(rng.integers(0, 256, (H, W + D, 3), dtype=np.uint8), (3, 3), 0)
    left, right = base[:, D:].copy(), base[:, D // 2 : D // 2 + W].copy()
    if channels == 1:
        return cv2.cvtColor(left, cv2.COLOR_RGB2GRAY), cv2.cvtColor(right, cv2.COLOR_RGB2GRAY)
    return left, right


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark (see the module docs)."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--reps", type=int, default=20, help="timed runs of each step (default 20)")
    add_output_args(ap, "bench_rectify")
    a = ap.parse_args(argv)
    left_cam, right_cam = _cameras()
    build_ms = median_ms(lambda: StereoRectifier(left_cam, right_cam), max(1, a.reps // 4))
    rect = StereoRectifier(left_cam, right_cam)
    float_maps = [cv2.initUndistortRectifyMap(c.k, c.d, c.r, c.p, (W, H), cv2.CV_32FC1) for c in (left_cam, right_cam)]
    matcher = build_matcher("census-sgm", {"max_disparity": D})
    rows: list[dict[str, object]] = []
    for channels in (3, 1):
        left, right = _pair(channels)
        frame = StereoFrame(left, right)
        rectify_ms = median_ms(lambda frame=frame: rect(frame), a.reps)
        float_ms = median_ms(
            lambda left=left, right=right: [
                cv2.remap(img, m[0], m[1], cv2.INTER_LINEAR) for img, m in zip((left, right), float_maps, strict=True)
            ],
            a.reps,
        )
        done = rect(frame)
        match_ms = median_ms(lambda done=done: matcher.compute(done.left, done.right), a.reps)
        rows.append(
            {
                "size": f"{W}x{H}",
                "channels": channels,
                "rectify_ms": round(rectify_ms, 3),
                "rectify_float_maps_ms": round(float_ms, 3),
                "census_sgm_ms": round(match_ms, 3),
                "rectify_share": round(rectify_ms / match_ms, 4),
            }
        )
    print(f"remap tables (once per calibration): {build_ms:.1f} ms")
    print("| image | rectify (fixed-point) ms | rectify (float maps) ms | census-SGM ms | rectify / census-SGM |")
    print("|---|---|---|---|---|")
    for r in rows:
        kind = "RGB" if r["channels"] == 3 else "gray"
        print(
            f"| {r['size']} {kind} | {r['rectify_ms']:.2f} | {r['rectify_float_maps_ms']:.2f} | "
            f"{r['census_sgm_ms']:.1f} | {100 * float(r['rectify_share']):.1f} % |"
        )
    out = write_report(output_path(a, "bench_rectify"), rows, reps=a.reps, maps_build_ms=round(build_ms, 2))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
