"""Make docs/img/see_through.png: see-through points of an offset LiDAR on KITTI 2012 000070, and the filter.

The ``lidar`` sensor at ``pose = "kitti"`` (0.27 m behind, 0.075 m above the left
camera); points within 1 px of the ground truth in green, see-through points
(more than 1 px behind it) in red, points the see-through filter drops ringed in black.
Reads the shared data in place (``<repo>/../shared/data``).

Usage: ``python scripts/make_see_through_figure.py [--out docs/img/see_through.png]``.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

import matplotlib as mpl
import matplotlib.pyplot as plt
import numpy as np

from vpp_service.datasets import open_dataset
from vpp_service.fusion import DEFAULT_DEPTH_FILTER
from vpp_service.sources.sensors import build_sensor

KITTI = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "kitti2012_training"


def main(argv: Sequence[str] | None = None) -> int:
    """Simulate the scan, classify its points against the ground truth and save the figure to ``--out``."""
    mpl.use("Agg")
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--out", default="docs/img/see_through.png")
    a = ap.parse_args(argv)
    frame = open_dataset("auto", KITTI)[0]
    gt = frame.gt_disparity
    sparse = build_sensor("lidar", {"pose": "kitti"}).simulate(frame, 0).sparse_disparity
    assert gt is not None and sparse is not None
    kept, _ = DEFAULT_DEPTH_FILTER(sparse)
    have = np.isfinite(sparse) & np.isfinite(gt)
    err = np.where(have, sparse - np.where(np.isfinite(gt), gt, 0), 0)
    bad = have & (err < -1)  # behind the surface the camera sees
    good = have & (np.abs(err) <= 1)
    dropped = np.isfinite(sparse) & ~np.isfinite(kept)
    ys, xs = slice(120, 376), slice(0, 700)  # the cars on the left and the road
    gray = frame.left if frame.left.ndim == 2 else frame.left[..., 0]
    fig, ax = plt.subplots(figsize=(7.0, 2.7), dpi=100)
    ax.imshow(gray[ys, xs], cmap="gray", vmin=0, vmax=255)
    for mask, style in (
        (good, {"s": 1.5, "c": "#2ca02c", "label": "within 1 px of GT"}),
        (bad, {"s": 9, "c": "#ff2020", "label": "see-through (> 1 px behind GT)"}),
    ):
        r, c = np.nonzero(mask[ys, xs])
        ax.scatter(c, r, marker="s", linewidths=0, **style)
    r, c = np.nonzero(dropped[ys, xs])
    ax.scatter(c, r, s=14, facecolors="none", edgecolors="black", linewidths=0.5, label="dropped by the filter")
    ax.set_axis_off()
    ax.legend(loc="upper right", fontsize=6, markerscale=2, framealpha=0.8)
    fig.tight_layout(pad=0.1)
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(a.out)
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
