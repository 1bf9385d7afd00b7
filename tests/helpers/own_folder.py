"""A ``folder`` dataset as a user's own recording: images, calibration and ``sparse/``, no ground truth.

The pairs are scikit-image's Motorcycle scene (resized); the sparse points are a
seeded 5 % of its ground truth, written in the forms ``sparse/`` accepts. The
ground truth stays with the test (to score the outputs), not in the folder.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

from vpp_service.datasets.skimage_scene import motorcycle
from vpp_service.frame import StereoFrame
from vpp_service.sources.sim import scale_frame

#: The forms of ``sparse/<stem>.*`` (``vpp_service.datasets.sparse_input``), in frame order.
FORMS = ("png", "npy", "csv")


def own_scene(scale: float = 0.25) -> StereoFrame:
    """The Motorcycle frame (with its ground truth and calibration) at ``scale``."""
    return scale_frame(motorcycle(), scale)


def sparse_points(frame: StereoFrame, density: float = 0.05, seed: int = 0) -> np.ndarray:
    """H x W float32: ``density`` of the frame's valid ground-truth pixels, quantised to 1/256 px; NaN elsewhere."""
    gt = frame.gt_disparity
    assert gt is not None
    rng = np.random.default_rng(seed)
    pick = np.isfinite(gt) & (gt > 0) & (rng.random(gt.shape) < density)
    out = np.full(gt.shape, np.nan, np.float32)
    out[pick] = np.rint(gt[pick] * 256) / 256  # what a 16-bit PNG holds: every form carries the same values
    return out


def write_sparse(path: Path, sparse: np.ndarray) -> None:
    """``sparse`` (NaN = no point) as ``path``'s form: 16-bit PNG (x256), ``.npy`` or a ``u,v,d`` points file."""
    ext = path.suffix
    if ext == ".png":
        png = np.zeros(sparse.shape, np.uint16)
        ok = np.isfinite(sparse)
        png[ok] = np.rint(sparse[ok] * 256).astype(np.uint16)
        assert cv2.imwrite(str(path), png)
    elif ext == ".npy":
        np.save(path, sparse)
    else:
        ys, xs = np.nonzero(np.isfinite(sparse))
        rows = "".join(f"{x},{y},{float(sparse[y, x])!r}\n" for y, x in zip(ys, xs, strict=True))
        path.write_text("# my scanner, frame " + path.stem + "\nu,v,d\n" + rows)


def write_own_folder(root: Path, frame: StereoFrame, forms: tuple[str, ...] = FORMS) -> list[np.ndarray]:
    """``left/``, ``right/``, ``calib.json`` and ``sparse/`` (one form per frame) of ``frame``, repeated.

    Returns the sparse map of every frame (frame ``i`` uses seed ``i``).
    """
    for sub in ("left", "right", "sparse"):
        (root / sub).mkdir(parents=True, exist_ok=True)
    maps = []
    for i, form in enumerate(forms):
        stem = f"{i:03d}"
        assert cv2.imwrite(str(root / "left" / f"{stem}.png"), cv2.cvtColor(frame.left, cv2.COLOR_RGB2BGR))
        assert cv2.imwrite(str(root / "right" / f"{stem}.png"), cv2.cvtColor(frame.right, cv2.COLOR_RGB2BGR))
        sparse = sparse_points(frame, seed=i)
        write_sparse(root / "sparse" / f"{stem}.{form}", sparse)
        maps.append(sparse)
    assert frame.calib is not None
    (root / "calib.json").write_text(json.dumps(frame.calib.to_dict()))
    return maps
