"""Readers of the Middlebury stereo sets (2001, 2003, 2005/2006, 2014).

===============  =========================  =============================  ===========================
reader           images (left / right)      ground truth (left)            decode
===============  =========================  =============================  ===========================
middlebury2014   im0.png / im1.png          disp0GT.pfm or disp0.pfm       as stored, +inf invalid
middlebury2006   view1.png / view5.png      disp1.png (right: disp5.png)   value / ``scale`` (3), 0 inv.
middlebury2003   imL.png / imR.png          disp2.png (right: disp6.png)   value / ``scale`` (4), 0 inv.
middlebury2001   imL.png/imR.png (Tsukuba)  truedisp.pgm + nonocc.png      value / 16, 0 invalid
                 im2.ppm / im6.ppm          disp2.pgm (right: disp6.pgm)   value / 8, 0 invalid
===============  =========================  =============================  ===========================

Non-occlusion masks: 2014 reads ``mask0nocc.png`` (255 = non-occluded); 2001
Tsukuba reads ``nonocc.png``; the other older sets derive the mask from the
right-view ground truth with a left-right check (``meta["nocc_source"]``).
Only 2014 ships a calibration (``calib.txt``; baseline mm -> m).
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np

from vpp_service.datasets.base import DATASETS, Dataset, scene_dirs
from vpp_service.datasets.calibfile import middlebury_calibration, parse_middlebury_calib
from vpp_service.datasets.imageio import read_image, read_mask, read_scaled_disparity
from vpp_service.datasets.nocc import lr_consistency_mask
from vpp_service.datasets.pfm import read_pfm
from vpp_service.frame import StereoFrame

log = logging.getLogger(__name__)


def _check_scale(scale: float | None, arg: str = "scale") -> None:
    if scale is None:
        return
    if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not math.isfinite(scale) or scale <= 0:
        raise ValueError(f"{arg}: must be a finite number > 0, got {scale!r}")


def _check_tol(tol: float) -> None:
    if isinstance(tol, bool) or not isinstance(tol, (int, float)) or not math.isfinite(tol) or tol < 0:
        raise ValueError(f"lr_tol: must be a finite number >= 0, got {tol!r}")


def read_pfm_disparity(path: Path) -> np.ndarray:
    """A PFM disparity map with +inf / non-finite / <= 0 values turned into NaN."""
    d = read_pfm(path)
    if d.ndim == 3:
        d = d[..., 0]
    d = d.copy()
    d[~np.isfinite(d) | (d <= 0)] = np.nan
    return d


@DATASETS.register("middlebury2014")
class Middlebury2014(Dataset):
    """Middlebury 2014 / MiddEval3 scenes (``im0.png``, ``im1.png``, ``calib.txt``, ``disp0GT.pfm``).

    Parameters
    ----------
    root : str or Path
        Folder of scene folders (or one scene folder).
    """

    name = "middlebury2014"
    layout = "<scene>/im0.png, im1.png, calib.txt with vmin/vmax, disp0GT.pfm or disp0.pfm [mask0nocc.png]"

    @staticmethod
    def _is_scene(p: Path) -> bool:
        return (p / "im0.png").is_file() and (p / "im1.png").is_file() and (p / "calib.txt").is_file()

    #: Whether this set's ``calib.txt`` carries ``vmin`` (Middlebury 2014 does, ETH3D does not).
    calib_has_vmin = True

    @classmethod
    def _is_mine(cls, p: Path) -> bool:
        if not cls._is_scene(p):
            return False
        try:
            return ("vmin" in parse_middlebury_calib(p / "calib.txt")) == cls.calib_has_vmin
        except (ValueError, OSError):
            return False

    @classmethod
    def detect(cls, root: Path) -> bool:
        """True if ``root`` (or a sub-folder) is a scene whose ``calib.txt`` has ``vmin`` exactly when expected."""
        return bool(scene_dirs(root, cls._is_mine))

    def __init__(self, root: str | Path) -> None:
        super().__init__(root)
        self._dirs = scene_dirs(self.root, self._is_scene)
        if not self._dirs:
            raise ValueError(f"root: no scene with im0.png, im1.png and calib.txt in {self.root}")
        self.scenes = [p.name for p in self._dirs]
        ndisp = []
        for p in self._dirs:
            try:
                v = parse_middlebury_calib(p / "calib.txt").get("ndisp")
            except ValueError:
                v = None
            if isinstance(v, float):
                ndisp.append(v)
        self.max_disparity = max(ndisp) if ndisp else None

    def _gt_path(self, d: Path) -> Path | None:
        for name in ("disp0GT.pfm", "disp0.pfm"):
            if (d / name).is_file():
                return d / name
        return None

    def _load(self, index: int) -> StereoFrame:
        d = self._dirs[index]
        left, right = read_image(d / "im0.png"), read_image(d / "im1.png")
        calib = middlebury_calibration(parse_middlebury_calib(d / "calib.txt"))
        gt_path = self._gt_path(d)
        gt = read_pfm_disparity(gt_path) if gt_path else None
        nocc = None
        if (d / "mask0nocc.png").is_file():
            nocc = read_mask(d / "mask0nocc.png", threshold=255)
            if gt is not None:
                nocc &= np.isfinite(gt)
        meta = {"dataset": self.name, "path": str(d)}
        if nocc is not None:
            meta["nocc_source"] = "mask0nocc.png"
        return StereoFrame(
            left=left, right=right, calib=calib, gt_disparity=gt, nocc_mask=nocc, name=self.scenes[index], meta=meta
        )


class _OldMiddlebury(Dataset):
    """Shared code of the 2001-2006 readers: integer-coded disparity, no calibration."""

    left_name = ""
    right_name = ""
    gt_name = ""
    gt_right_name = ""
    default_scale = 1.0

    def __init__(self, root: str | Path, scale: float | None = None, lr_tol: float = 1.0) -> None:
        super().__init__(root)
        _check_scale(scale)
        _check_tol(lr_tol)
        self.scale = float(scale) if scale is not None else None
        self.lr_tol = float(lr_tol)
        self._dirs = scene_dirs(self.root, type(self)._is_scene)
        if not self._dirs:
            raise ValueError(f"root: no {self.name} scene ({self.layout}) in {self.root}")
        self.scenes = [p.name for p in self._dirs]
        self.max_disparity = float(math.ceil(255.0 / (self.scale or self.default_scale)))

    @classmethod
    def _is_scene(cls, p: Path) -> bool:
        return all((p / n).is_file() for n in (cls.left_name, cls.right_name, cls.gt_name))

    @classmethod
    def detect(cls, root: Path) -> bool:
        return bool(scene_dirs(root, cls._is_scene))

    def _scene_scale(self, d: Path) -> float:
        return self.scale or self.default_scale

    def _frame(
        self,
        index: int,
        left_path: Path,
        right_path: Path,
        gt_path: Path,
        *,
        gt_right_path: Path | None = None,
        nocc_path: Path | None = None,
    ) -> StereoFrame:
        """The frame of scene ``index``; its mask comes from ``nocc_path`` or else a check against ``gt_right_path``."""
        d = self._dirs[index]
        scale = self._scene_scale(d)
        gt = read_scaled_disparity(gt_path, scale)
        meta = {"dataset": self.name, "path": str(d), "scale": scale}
        nocc = None
        if nocc_path is not None and nocc_path.is_file():
            nocc = read_mask(nocc_path, threshold=255) & np.isfinite(gt)
            meta["nocc_source"] = nocc_path.name
        elif gt_right_path is not None and gt_right_path.is_file():
            gt_r = read_scaled_disparity(gt_right_path, scale)
            nocc = lr_consistency_mask(gt, gt_r, tol=self.lr_tol)
            meta["nocc_source"] = f"lr-check({gt_right_path.name})"
        return StereoFrame(
            left=read_image(left_path),
            right=read_image(right_path),
            calib=None,
            gt_disparity=gt,
            nocc_mask=nocc,
            name=self.scenes[index],
            meta=meta,
        )

    def _load(self, index: int) -> StereoFrame:
        d = self._dirs[index]
        return self._frame(
            index, d / self.left_name, d / self.right_name, d / self.gt_name, gt_right_path=d / self.gt_right_name
        )


@DATASETS.register("middlebury2006")
class Middlebury2006(_OldMiddlebury):
    """Middlebury 2005/2006 scenes (``view1.png``, ``view5.png``, ``disp1.png``).

    Parameters
    ----------
    root : str or Path
        Folder of scene folders (or one scene).
    scale : float, optional
        Disparity divisor (3 for third size, 2 half, 1 full). Default 3.
    lr_tol : float
        Tolerance (px) of the left-right check that derives ``nocc_mask`` from ``disp5.png``.
    """

    name = "middlebury2006"
    layout = "<scene>/view1.png, view5.png, disp1.png [disp5.png]"
    left_name, right_name, gt_name, gt_right_name = "view1.png", "view5.png", "disp1.png", "disp5.png"
    default_scale = 3.0


@DATASETS.register("middlebury2003")
class Middlebury2003(_OldMiddlebury):
    """Middlebury 2003 scenes (``imL.png``, ``imR.png``, ``disp2.png``; Cones, Teddy).

    Parameters
    ----------
    root : str or Path
        Folder of scene folders (or one scene).
    scale : float, optional
        Disparity divisor (4 for quarter size). Default 4.
    lr_tol : float
        Tolerance (px) of the left-right check that derives ``nocc_mask`` from ``disp6.png``.
    """

    name = "middlebury2003"
    layout = "<scene>/imL.png, imR.png, disp2.png [disp6.png]"
    left_name, right_name, gt_name, gt_right_name = "imL.png", "imR.png", "disp2.png", "disp6.png"
    default_scale = 4.0


@DATASETS.register("middlebury2001")
class Middlebury2001(_OldMiddlebury):
    """Middlebury 2001 scenes: Tsukuba and the piecewise-planar scenes.

    Tsukuba ships ``imL.png``, ``imR.png``, ``truedisp.pgm`` and ``nonocc.png``; the
    piecewise-planar scenes ship ``im2.ppm``, ``im6.ppm`` and ``disp2.pgm``.

    Scenes without a lossless left *and* right image are skipped with a warning,
    unless ``allow_jpeg=True`` lets a JPEG stand in (bull ships ``im2.jpg`` only).

    Parameters
    ----------
    root : str or Path
        Folder of scene folders (or one scene).
    scale : float, optional
        Disparity divisor for every scene; default 16 for Tsukuba and 8 for the others.
    lr_tol : float
        Tolerance (px) of the left-right check that derives ``nocc_mask`` from ``disp6.pgm``.
    allow_jpeg : bool
        Accept ``im2.jpg`` / ``im6.jpg`` when the PPM is missing. Default False.
    """

    name = "middlebury2001"
    layout = "Tsukuba/imL.png, imR.png, truedisp.pgm | <scene>/im2.ppm, im6.ppm, disp2.pgm"
    default_scale = 8.0

    def __init__(
        self, root: str | Path, scale: float | None = None, lr_tol: float = 1.0, allow_jpeg: bool = False
    ) -> None:
        self.allow_jpeg = bool(allow_jpeg)
        Dataset.__init__(self, root)
        _check_scale(scale)
        _check_tol(lr_tol)
        self.scale = float(scale) if scale is not None else None
        self.lr_tol = float(lr_tol)
        candidates = scene_dirs(self.root, self._has_gt)
        self._dirs = []
        for d in candidates:
            if self._pair(d) is None:
                log.warning(
                    "middlebury2001: skipping scene %s: no lossless left and right image "
                    "(pass allow_jpeg=True to use a JPEG)",
                    d.name,
                )
                continue
            self._dirs.append(d)
        if not self._dirs:
            raise ValueError(f"root: no usable middlebury2001 scene ({self.layout}) in {self.root}")
        self.scenes = [p.name for p in self._dirs]
        self.max_disparity = 32.0 if self.scale is None else float(math.ceil(255.0 / self.scale))

    @staticmethod
    def _has_gt(p: Path) -> bool:
        return (p / "truedisp.pgm").is_file() or (p / "disp2.pgm").is_file()

    _is_scene = _has_gt

    def _pair(self, d: Path) -> tuple[Path, Path] | None:
        if (d / "truedisp.pgm").is_file():
            names = [("imL.png", "imR.png")]
        else:
            names = [("im2.ppm", "im6.ppm")]
            if self.allow_jpeg:
                names += [("im2.jpg", "im6.ppm"), ("im2.ppm", "im6.jpg"), ("im2.jpg", "im6.jpg")]
        for ln, rn in names:
            if (d / ln).is_file() and (d / rn).is_file():
                return d / ln, d / rn
        return None

    def _scene_scale(self, d: Path) -> float:
        if self.scale is not None:
            return self.scale
        return 16.0 if (d / "truedisp.pgm").is_file() else 8.0

    def _load(self, index: int) -> StereoFrame:
        d = self._dirs[index]
        pair = self._pair(d)
        if pair is None:  # files removed since construction
            raise FileNotFoundError(f"root: scene {d} lost its images")
        if (d / "truedisp.pgm").is_file():
            return self._frame(index, pair[0], pair[1], d / "truedisp.pgm", nocc_path=d / "nonocc.png")
        frame = self._frame(index, pair[0], pair[1], d / "disp2.pgm", gt_right_path=d / "disp6.pgm")
        if pair[0].suffix == ".jpg" or pair[1].suffix == ".jpg":
            frame.meta["lossy"] = True
        return frame


__all__ = ["Middlebury2001", "Middlebury2003", "Middlebury2006", "Middlebury2014", "read_pfm_disparity"]
