r"""Parsing of the calibration text files shipped with stereo benchmarks.

* Middlebury 2014 / ETH3D ``calib.txt``: ``key=value`` lines, where ``cam0`` and
  ``cam1`` are 3x3 matrices written ``[f 0 cx; 0 f cy; 0 0 1]`` and the
  ``baseline`` is in millimetres.
* KITTI ``calib/<id>.txt`` (and ``calib_cam_to_cam`` / ``calib_velo_to_cam``):
  ``key: v1 v2 ...`` lines of row-major matrices (``P0``..``P3`` are 3x4).

Both parsers are whitespace tolerant (spaces around ``=``, ``;`` or ``,`` as
row separators, blank lines, ``\r\n`` line ends).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import numpy.typing as npt

from vpp_service.frame import Calibration

#: A parsed Middlebury ``calib.txt``: 3x3 matrices (``cam0``, ``cam1``), numbers, or the raw text of other values.
MiddleburyCalib = dict[str, float | str | npt.NDArray[np.float64]]


def _numbers(text: str) -> list[float]:
    return [float(t) for t in re.split(r"[\s,;\[\]]+", text.strip()) if t]


def parse_middlebury_calib(path: str | Path) -> MiddleburyCalib:
    """Parse a Middlebury-2014 / ETH3D ``calib.txt``.

    Returns
    -------
    dict
        Keys as in the file; matrices (``cam0``, ``cam1``) as 3x3 float arrays,
        other values as floats (or the raw string when not numeric).

    Raises
    ------
    FileNotFoundError, ValueError
        Missing file, or a ``cam`` entry that is not 9 numbers.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"path: calibration file not found: {path}")
    out: MiddleburyCalib = {}
    for line in path.read_text().splitlines():
        if "=" not in line:
            continue
        key, _, value = line.partition("=")
        key, value = key.strip(), value.strip()
        if not key:
            continue
        if "[" in value:
            nums = _numbers(value)
            if len(nums) != 9:
                raise ValueError(f"path: {path}: {key} must be a 3x3 matrix, got {len(nums)} numbers")
            out[key] = np.array(nums, dtype=np.float64).reshape(3, 3)
        else:
            try:
                out[key] = float(value)
            except ValueError:
                out[key] = value
    return out


def middlebury_calibration(calib: MiddleburyCalib, scale: float = 1.0) -> Calibration:
    """Build a :class:`Calibration` from a parsed ``calib.txt`` (baseline mm -> m).

    Parameters
    ----------
    calib : dict
        Output of :func:`parse_middlebury_calib`; needs ``cam0`` and ``baseline``.
    scale : float
        Image scale factor relative to the calibration (e.g. 0.5 for half size);
        f, cx, cy and doffs scale with it.
    """
    cam0 = calib.get("cam0")
    if not isinstance(cam0, np.ndarray) or "baseline" not in calib:
        raise ValueError("calib: needs cam0=[...] and baseline=... entries")
    cam1 = calib.get("cam1")
    doffs = calib.get("doffs", 0.0)
    if not isinstance(doffs, float):
        doffs = 0.0
    if doffs == 0.0 and isinstance(cam1, np.ndarray):
        doffs = float(cam1[0, 2] - cam0[0, 2])
    return Calibration(
        f=float(cam0[0, 0]) * scale,
        baseline=float(calib["baseline"]) / 1000.0,
        doffs=float(doffs) * scale,
        cx=float(cam0[0, 2]) * scale,
        cy=float(cam0[1, 2]) * scale,
    )


def parse_kitti_calib(path: str | Path) -> dict[str, np.ndarray]:
    """Parse a KITTI ``key: numbers`` calibration file into float64 arrays.

    Entries with 12 numbers are returned as 3x4, with 9 numbers as 3x3, others
    flat. Non-numeric entries (e.g. ``calib_time``) are skipped.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"path: calibration file not found: {path}")
    out: dict[str, np.ndarray] = {}
    for line in path.read_text().splitlines():
        if ":" not in line:
            continue
        key, _, value = line.partition(":")
        try:
            nums = np.array(_numbers(value), dtype=np.float64)
        except ValueError:
            continue
        if nums.size == 12:
            nums = nums.reshape(3, 4)
        elif nums.size == 9:
            nums = nums.reshape(3, 3)
        out[key.strip()] = nums
    return out


def kitti_calibration(p_left: np.ndarray, p_right: np.ndarray) -> Calibration:
    """Calibration of a rectified KITTI pair from its two 3x4 projection matrices.

    ``f = P_left[0,0]``, ``baseline = (P_left[0,3] - P_right[0,3]) / f`` metres,
    principal point from ``P_left``; ``doffs = 0``.
    """
    p_left = np.asarray(p_left, dtype=np.float64).reshape(3, 4)
    p_right = np.asarray(p_right, dtype=np.float64).reshape(3, 4)
    f = float(p_left[0, 0])
    baseline = float(p_left[0, 3] - p_right[0, 3]) / f
    return Calibration(f=f, baseline=baseline, doffs=0.0, cx=float(p_left[0, 2]), cy=float(p_left[1, 2]))


__all__ = [
    "MiddleburyCalib",
    "kitti_calibration",
    "middlebury_calibration",
    "parse_kitti_calib",
    "parse_middlebury_calib",
]
