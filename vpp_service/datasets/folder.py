"""The generic ``folder`` dataset layout, for your own recordings.

::

    root/
      left/    000.png 001.png ...      (any 8-bit PNG/PPM/PGM/JPEG; sorted by name)
      right/   000.png 001.png ...      (same count, paired by sorted position)
      disp/    000.pfm | 000.png | 000.npy   (optional left ground truth)
      nocc/    000.png                  (optional mask, 255 = non-occluded)
      sparse/  000.png | 000.npy | 000.csv | 000.txt   (optional: your own sparse depth, per frame)
      calib.json                        (optional {"f": ..., "baseline": ..., "doffs", "cx", "cy"})

Ground truth decoding: ``.pfm`` and ``.npy`` as stored (non-finite or <= 0 ->
NaN); ``.png``/``.pgm`` integer-coded, divided by ``disp_scale`` (default 256,
KITTI style), 0 invalid. Scene names are the left file stems.

``sparse/`` holds the sparse depth of your own recordings (a disparity image,
a disparity map, or a points file of ``u v d`` or ``x y z``; formats in
:mod:`vpp_service.datasets.sparse_input`), one file per frame named after its
left image (``sparse/000.png`` for ``left/000.png``). Frames with it need no
ground truth: the ``files`` source replays them with their own points instead
of simulating a sensor. With ``sparse/`` present every frame needs its file: a
frame whose file is missing or bad fails to load (a replay rejects and counts
that frame only).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from vpp_service.datasets.base import DATASETS, Dataset
from vpp_service.datasets.imageio import read_image, read_mask, read_scaled_disparity
from vpp_service.datasets.middlebury import read_pfm_disparity
from vpp_service.datasets.sparse_input import SPARSE_EXT, read_sparse
from vpp_service.frame import Calibration, StereoFrame

_IMAGE_EXT = {".png", ".ppm", ".pgm", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff"}
_DISP_EXT = {".pfm", ".png", ".pgm", ".npy"}


def _files(d: Path, exts: set[str]) -> list[Path]:
    return sorted(p for p in d.iterdir() if p.is_file() and p.suffix.lower() in exts) if d.is_dir() else []


@DATASETS.register("folder")
class FolderDataset(Dataset):
    """Generic ``left/``, ``right/``, ``[disp/]``, ``[nocc/]``, ``[sparse/]``, ``[calib.json]`` layout.

    Parameters
    ----------
    root : str or Path
        The folder holding ``left/`` and ``right/``.
    disp_scale : float
        Divisor of integer-coded (PNG/PGM) ground truth. Default 256.
    """

    name = "folder"
    layout = (
        "left/*.png, right/*.png (same count) [disp/*.pfm|png|npy] [nocc/*.png] [sparse/*.png|npy|csv|txt] [calib.json]"
    )

    @classmethod
    def detect(cls, root: Path) -> bool:
        """True if ``root`` has image files in both ``left/`` and ``right/``."""
        return bool(_files(root / "left", _IMAGE_EXT)) and bool(_files(root / "right", _IMAGE_EXT))

    def __init__(self, root: str | Path, disp_scale: float = 256.0) -> None:
        super().__init__(root)
        if (
            isinstance(disp_scale, bool)
            or not isinstance(disp_scale, (int, float))
            or not np.isfinite(disp_scale)
            or disp_scale <= 0
        ):
            raise ValueError(f"disp_scale: must be a finite number > 0, got {disp_scale!r}")
        self.disp_scale = float(disp_scale)
        self._left = _files(self.root / "left", _IMAGE_EXT)
        self._right = _files(self.root / "right", _IMAGE_EXT)
        if not self._left:
            raise ValueError(f"root: no images in {self.root / 'left'}")
        if len(self._left) != len(self._right):
            raise ValueError(f"root: {len(self._left)} left images but {len(self._right)} right images in {self.root}")
        disp = _files(self.root / "disp", _DISP_EXT)
        if disp and len(disp) != len(self._left):
            raise ValueError(f"root: {len(disp)} disparity files for {len(self._left)} left images in {self.root}")
        self._disp: list[Path | None] = list(disp) if disp else [None] * len(self._left)
        nocc = _files(self.root / "nocc", _IMAGE_EXT)
        if nocc and len(nocc) != len(self._left):
            raise ValueError(f"root: {len(nocc)} nocc masks for {len(self._left)} left images in {self.root}")
        self._nocc: list[Path | None] = list(nocc) if nocc else [None] * len(self._left)
        self.has_ground_truth = bool(disp)
        self._sparse = self._sparse_files()
        self.has_sparse_input = self._sparse is not None
        self.calib = None
        if (self.root / "calib.json").is_file():
            self.calib = Calibration.from_dict(json.loads((self.root / "calib.json").read_text()))
        self.scenes = [p.stem for p in self._left]

    def _subset(self, keep: list[int]) -> None:
        super()._subset(keep)
        for attr in ("_left", "_right", "_disp", "_nocc"):
            seq = getattr(self, attr)
            setattr(self, attr, [seq[i] for i in keep])
        if self._sparse is not None:
            self._sparse = [self._sparse[i] for i in keep]

    def _sparse_files(self) -> list[Path] | None:
        """``sparse/<left stem>.<ext>`` of every frame (None without ``sparse/``); the file may be missing."""
        folder = self.root / "sparse"
        if not folder.is_dir():
            return None
        found: dict[str, Path] = {}
        for p in _files(folder, set(SPARSE_EXT)):
            if p.stem in found:
                raise ValueError(f"root: two sparse inputs for frame {p.stem!r}: {found[p.stem].name} and {p.name}")
            found[p.stem] = p
        if not found:
            raise ValueError(f"root: {folder} holds no {', '.join(SPARSE_EXT)} files (remove it, or add them)")
        stems = {p.stem for p in self._left}
        strays = sorted(set(found) - stems)
        if strays:
            raise ValueError(f"root: {folder}: {strays[0]} matches no left image (sparse files are named after them)")
        # a frame without its file is kept: it fails alone when loaded (a replay counts it)
        return [found.get(p.stem, folder / f"{p.stem}{SPARSE_EXT[0]}") for p in self._left]

    def _read_disp(self, path: Path) -> np.ndarray:
        if path.suffix.lower() == ".pfm":
            return read_pfm_disparity(path)
        if path.suffix.lower() == ".npy":
            d = np.load(path).astype(np.float32)
            if d.ndim != 2:
                raise ValueError(f"path: {path} must hold a 2-D array, got shape {d.shape}")
            d[~np.isfinite(d) | (d <= 0)] = np.nan
            return d
        return read_scaled_disparity(path, self.disp_scale)

    def _load(self, index: int) -> StereoFrame:
        left, right = read_image(self._left[index]), read_image(self._right[index])
        if left.shape != right.shape:
            raise ValueError(f"root: {self._left[index].name} and {self._right[index].name} differ in shape")
        disp_path, nocc_path = self._disp[index], self._nocc[index]
        gt = self._read_disp(disp_path) if disp_path is not None else None
        nocc = read_mask(nocc_path, threshold=255) if nocc_path is not None else None
        if disp_path is not None and gt is not None and gt.shape != left.shape[:2]:
            raise ValueError(f"root: ground truth {disp_path.name} shape {gt.shape} != image {left.shape[:2]}")
        meta: dict[str, object] = {"dataset": self.name, "path": str(self._left[index])}
        sparse = None
        if self._sparse is not None:
            path = self._sparse[index]
            if not path.is_file():
                raise FileNotFoundError(
                    f"sparse: no sparse input for frame {self.scenes[index]!r} "
                    f"(sparse/{self.scenes[index]}{{{','.join(SPARSE_EXT)}}})"
                )
            sparse, meta["lidar_like"] = read_sparse(path, left.shape[:2], self.calib, self.disp_scale)
        return StereoFrame(
            left=left,
            right=right,
            calib=self.calib,
            sparse_disparity=sparse,
            gt_disparity=gt,
            nocc_mask=nocc,
            name=self.scenes[index],
            meta=meta,
        )


__all__ = ["FolderDataset"]
