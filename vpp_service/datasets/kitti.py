"""Readers of the KITTI stereo 2012 and 2015 training sets.

Layout of a KITTI folder ``D`` (the dataset root itself, or each sub-folder of
it that has this layout; the shared sample keeps one frame per sub-folder):

=============  =============================  ================================
               kitti2012                      kitti2015
=============  =============================  ================================
left / right   image_0 / image_1 (gray),      image_2 / image_3 (RGB)
               colored_0 / colored_1 (RGB,
               ``color=True``)
ground truth   disp_occ / disp_noc            disp_occ_0 / disp_noc_0
calibration    calib/<id>.txt (P0..P3)        calib/<id>.txt or
                                              calib_cam_to_cam/<id>.txt (P_rect_0i)
LiDAR          velodyne/<id>.bin + Tr_velo_to_cam (+ R0_rect) in the calib file, or
               calib_velo_to_cam/<id>.txt (R, T)
=============  =============================  ================================

Ground truth is ``uint16 / 256`` with 0 invalid; ``gt="occ"`` (default) gives
all pixels, ``nocc_mask`` is the validity of the ``noc`` map. Frames are the
``<id>_10`` files of the ground-truth folder (the image folder when there is no
ground truth). When a Velodyne scan and its extrinsics exist, it is projected
into ``sensor_depth`` (metres, 0 = none) and converted to ``sparse_disparity``.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import ClassVar

import numpy as np

from vpp_service.datasets.base import DATASETS, Dataset, scene_dirs
from vpp_service.datasets.calibfile import kitti_calibration, parse_kitti_calib
from vpp_service.datasets.imageio import read_image, read_scaled_disparity
from vpp_service.datasets.velodyne import project_points, read_velodyne_bin, velo_to_camera
from vpp_service.frame import StereoFrame
from vpp_service.vpp.see_through import LIDAR_LIKE

log = logging.getLogger(__name__)


class _Kitti(Dataset):
    """Shared code of the KITTI readers."""

    #: color -> (left image folder, right image folder, index of P for the left, for the right).
    pairs: ClassVar[dict[bool, tuple[str, str, int, int]]] = {}
    #: ground-truth kind ("occ", "noc") -> folder.
    gt_dirs: ClassVar[dict[str, str]] = {}
    default_color = False

    @classmethod
    def _is_seq(cls, p: Path) -> bool:
        left, right, _, _ = cls.pairs[cls.default_color]
        return (p / left).is_dir() and (p / right).is_dir() and any((p / g).is_dir() for g in cls.gt_dirs.values())

    @classmethod
    def detect(cls, root: Path) -> bool:
        return bool(scene_dirs(root, cls._is_seq))

    def __init__(self, root: str | Path, color: bool | None = None, gt: str = "occ") -> None:
        super().__init__(root)
        if color is None:
            color = self.default_color
        if not isinstance(color, bool) or color not in self.pairs:
            raise ValueError(f"color: must be one of {sorted(self.pairs)}, got {color!r}")
        if gt not in self.gt_dirs:
            raise ValueError(f"gt: must be one of {sorted(self.gt_dirs)}, got {gt!r}")
        self.color, self.gt = color, gt
        self.left_dir, self.right_dir, self.p_left, self.p_right = self.pairs[color]
        seqs = scene_dirs(self.root, lambda p: (p / self.left_dir).is_dir() and (p / self.right_dir).is_dir())
        self._items: list[tuple[Path, str]] = []
        for seq in seqs:
            src = seq / self.gt_dirs[gt]
            if not src.is_dir():
                src = seq / self.left_dir
            for f in sorted(src.glob("*_10.png")):
                if (seq / self.left_dir / f.name).is_file() and (seq / self.right_dir / f.name).is_file():
                    self._items.append((seq, f.stem))
        if not self._items:
            raise ValueError(f"root: no {self.name} frame ({self.layout}) in {self.root}")
        self.scenes = [stem if seq == self.root else f"{seq.name}/{stem}" for seq, stem in self._items]
        self.max_disparity = 256.0

    def _subset(self, keep: list[int]) -> None:
        super()._subset(keep)
        self._items = [self._items[i] for i in keep]

    def _calib_entries(self, seq: Path, frame_id: str) -> dict[str, np.ndarray]:
        entries: dict[str, np.ndarray] = {}
        for sub in ("calib_cam_to_cam", "calib", "calib_velo_to_cam"):
            path = seq / sub / f"{frame_id}.txt"
            if path.is_file():
                parsed = parse_kitti_calib(path)
                if sub == "calib_velo_to_cam" and "R" in parsed and "T" in parsed:
                    parsed["Tr_velo_to_cam"] = np.hstack([parsed["R"].reshape(3, 3), parsed["T"].reshape(3, 1)])
                entries.update(parsed)
        return entries

    @staticmethod
    def _projection(entries: dict[str, np.ndarray], i: int) -> np.ndarray | None:
        for key in (f"P{i}", f"P_rect_0{i}"):
            if key in entries and entries[key].size == 12:
                return entries[key].reshape(3, 4)
        return None

    def _load(self, index: int) -> StereoFrame:
        seq, stem = self._items[index]
        frame_id = stem.split("_")[0]
        left = read_image(seq / self.left_dir / f"{stem}.png")
        right = read_image(seq / self.right_dir / f"{stem}.png")
        gt = nocc = None
        gt_path = seq / self.gt_dirs[self.gt] / f"{stem}.png"
        if gt_path.is_file():
            gt = read_scaled_disparity(gt_path, 256.0)
        noc_path = seq / self.gt_dirs["noc"] / f"{stem}.png"
        if noc_path.is_file():
            nocc = np.isfinite(read_scaled_disparity(noc_path, 256.0))
            if gt is not None:
                nocc &= np.isfinite(gt)
        entries = self._calib_entries(seq, frame_id)
        p_l, p_r = self._projection(entries, self.p_left), self._projection(entries, self.p_right)
        calib = kitti_calibration(p_l, p_r) if p_l is not None and p_r is not None else None
        meta: dict[str, object] = {"dataset": self.name, "path": str(seq), "frame_id": stem}
        sensor_depth = sparse = None
        velo = seq / "velodyne" / f"{frame_id}.bin"
        if velo.is_file() and calib is not None and p_l is not None and "Tr_velo_to_cam" in entries:
            r0 = entries.get("R0_rect", entries.get("R_rect_00"))
            cam = velo_to_camera(read_velodyne_bin(velo), entries["Tr_velo_to_cam"], r0)
            sensor_depth = project_points(cam, p_l, left.shape[:2])
            sparse = np.full(sensor_depth.shape, np.nan, np.float32)
            hit = sensor_depth > 0
            sparse[hit] = calib.f * calib.baseline / sensor_depth[hit] - calib.doffs
            meta["sensor"] = "velodyne"
            meta[LIDAR_LIKE] = True  # the Velodyne is 0.27 m behind the camera: its scan sees past edges
        elif velo.is_file():
            log.warning("%s: %s has no Tr_velo_to_cam calibration; scan ignored", self.name, velo)
        return StereoFrame(
            left=left,
            right=right,
            calib=calib,
            gt_disparity=gt,
            nocc_mask=nocc,
            sensor_depth=sensor_depth,
            sparse_disparity=sparse,
            name=self.scenes[index],
            meta=meta,
        )


@DATASETS.register("kitti2012")
class Kitti2012(_Kitti):
    """KITTI stereo 2012 (``image_0``/``image_1`` gray, ``colored_0``/``colored_1`` RGB).

    Parameters
    ----------
    root : str or Path
        The training folder (or a folder of such folders).
    color : bool
        False (default): the gray pair the ground truth is registered to; True: the RGB pair.
    gt : {"occ", "noc"}
        Ground truth of all pixels (default) or of the non-occluded ones only.
    """

    name = "kitti2012"
    layout = "image_0/, image_1/ [colored_0/, colored_1/], disp_occ/ or disp_noc/ <id>_10.png, calib/<id>.txt"
    pairs: ClassVar[dict[bool, tuple[str, str, int, int]]] = {
        False: ("image_0", "image_1", 0, 1),
        True: ("colored_0", "colored_1", 2, 3),
    }
    gt_dirs: ClassVar[dict[str, str]] = {"occ": "disp_occ", "noc": "disp_noc"}


@DATASETS.register("kitti2015")
class Kitti2015(_Kitti):
    """KITTI stereo 2015 (``image_2``/``image_3`` RGB).

    Parameters
    ----------
    root : str or Path
        The training folder (or a folder of such folders).
    color : bool
        Only True (RGB) exists in this set; default True.
    gt : {"occ", "noc"}
        Ground truth of all pixels (default) or of the non-occluded ones only.
    """

    name = "kitti2015"
    layout = "image_2/, image_3/, disp_occ_0/ or disp_noc_0/ <id>_10.png, calib/ or calib_cam_to_cam/<id>.txt"
    pairs: ClassVar[dict[bool, tuple[str, str, int, int]]] = {True: ("image_2", "image_3", 2, 3)}
    gt_dirs: ClassVar[dict[str, str]] = {"occ": "disp_occ_0", "noc": "disp_noc_0"}
    default_color = True


__all__ = ["Kitti2012", "Kitti2015"]
