"""OpenCV block matchers: ``sgbm`` (cv2.StereoSGBM) and ``bm`` (cv2.StereoBM).

Conventions shared with the other matchers (see :mod:`vpp_service.matchers.base`):
OpenCV returns fixed-point disparities (x16, int16); they are divided by 16
into float32 and every value below ``min_disparity`` (OpenCV's "invalid",
``(min_disparity - 1) * 16``) becomes NaN. OpenCV needs ``numDisparities`` to be
a multiple of 16: ``max_disparity`` is rounded **up** to the next multiple of
16 (e.g. 100 -> 112), and the rounded value must still be below the width.

Left band: OpenCV itself leaves the leftmost ``min_disparity + numDisparities``
columns invalid (no full search range there). Both wrappers give them a
disparity (option ``left_band``, default ``"replicate"``): the two images are
padded on the left by that many columns, replicating their first column, the
pair is matched, and the padding is cropped off the result. A pixel ``x`` of
the band then searches every disparity ``0 .. D-1``; those with ``x - d >= 0``
land inside the right image, the others on the replicated column (which the
left-right check and uniqueness test mostly reject). ``"constant"`` pads with
black instead; ``"off"`` keeps OpenCV's empty band. Replicate scores best on
the 26 Middlebury 2005/2006 scenes for both matchers;
the padding costs matching time in proportion, ``D / W`` more columns.

Colour: ``sgbm`` matches the colour image directly (StereoSGBM sums the
per-channel costs, and the default penalties scale with the channel count
``cn``), which keeps the colour information VPP paints; ``bm`` only takes gray,
so RGB is converted with the usual luminance weights.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Literal

import cv2
import numpy as np

from vpp_service.matchers.base import MATCHERS, DisparityRangeError, Matcher, MatcherOptions, MatcherRuntime
from vpp_service.matchers.inputs import to_gray
from vpp_service.settings import Odd, Range, reject

_SGBM_MODES = {
    "sgbm": cv2.STEREO_SGBM_MODE_SGBM,
    "hh": cv2.STEREO_SGBM_MODE_HH,
    "3way": cv2.STEREO_SGBM_MODE_SGBM_3WAY,
    "hh4": cv2.STEREO_SGBM_MODE_HH4,
}


def opencv_num_disparities(max_disparity: int) -> int:
    """``max_disparity`` rounded up to a multiple of 16 (OpenCV's numDisparities)."""
    return int(-(-int(max_disparity) // 16) * 16)


def _to_float(raw: np.ndarray, min_disparity: int, pad: int = 0) -> np.ndarray:
    """OpenCV's x16 fixed point -> float32 (NaN = invalid), the ``pad`` left columns cropped off."""
    if pad:
        raw = raw[:, pad:]
    disp = raw.astype(np.float32)
    disp *= 1.0 / 16.0
    disp[raw < min_disparity * 16] = np.nan
    return disp


#: ``cv2.copyMakeBorder`` mode of each ``left_band`` choice.
_BORDERS = {"constant": cv2.BORDER_CONSTANT, "replicate": cv2.BORDER_REPLICATE}


def _pad_left(img: np.ndarray, pad: int, band: str) -> np.ndarray:
    """``img`` with ``pad`` columns added on the left (``band`` = "off": unchanged)."""
    if band == "off" or pad <= 0:
        return img
    return cv2.copyMakeBorder(img, 0, 0, pad, 0, _BORDERS[band], value=0)


def opencv_runtime() -> MatcherRuntime:
    """What runs ``sgbm`` and ``bm``: OpenCV on the CPU, int16 costs (and 1/16 px disparities), its threads."""
    return {"engine": "opencv", "device": "cpu", "precision": "int16", "threads": int(cv2.getNumThreads())}


def _check_width(max_disparity: int, min_disparity: int, width: int) -> int:
    """OpenCV's ``numDisparities``; :class:`DisparityRangeError` when it plus ``min_disparity`` reaches ``width``."""
    nd = opencv_num_disparities(max_disparity)
    if min_disparity + nd >= width:
        raise DisparityRangeError(
            f"max_disparity {max_disparity} (rounded up to {nd} for OpenCV) + min_disparity "
            f"{min_disparity} must be < the image width {width}"
        )
    return nd


@dataclass(frozen=True)
class SGBMOptions(MatcherOptions):
    """Options of the ``sgbm`` matcher (cv2.StereoSGBM).

    Attributes
    ----------
    mode : {"3way", "sgbm", "hh", "hh4"}
        OpenCV mode: SGBM 3-way (default, 5 directions, fast), SGBM
        (5 directions), HH (full 8 directions) or HH4.
    block_size : int
        Odd matching block size in [1, 11], default 5.
    p1, p2 : int
        Smoothness penalties; 0 = OpenCV's usual ``8 cn bs^2`` and ``32 cn bs^2``
        (cn = channel count, bs = block size). ``p2`` must exceed ``p1``.
    min_disparity : int
        Smallest disparity searched (>= 0; default 0).
    uniqueness : int
        Uniqueness ratio in percent (default 10).
    speckle_window, speckle_range : int
        Speckle filter: max region size (0 = off, default 100) and max
        disparity variation inside it (pixels, default 2).
    disp12_max_diff : int
        Left-right check tolerance in pixels (default 1; -1 = off).
    pre_filter_cap : int
        Pre-filter truncation (default 63).
    left_band : {"constant", "replicate", "off"}
        How the leftmost ``min_disparity + numDisparities`` columns get a
        disparity: both images are padded on the left by that many columns
        (``"replicate"`` of the first column, default, or black ``"constant"``)
        and the result is cropped; ``"off"`` leaves them NaN as OpenCV does.
    """

    mode: Literal["3way", "sgbm", "hh", "hh4"] = "3way"
    block_size: Annotated[int, Range(1, 11), Odd()] = 5
    p1: Annotated[int, Range(0)] = 0
    p2: Annotated[int, Range(0)] = 0
    min_disparity: Annotated[int, Range(0)] = 0
    uniqueness: Annotated[int, Range(0)] = 10
    speckle_window: Annotated[int, Range(0)] = 100
    speckle_range: Annotated[int, Range(0)] = 2
    disp12_max_diff: Annotated[int, Range(-1)] = 1
    pre_filter_cap: Annotated[int, Range(1, 63)] = 63
    left_band: Literal["constant", "replicate", "off"] = "replicate"

    def cross_check(self) -> None:
        """``p2`` above ``p1`` once either is set."""
        super().cross_check()
        if (self.p1 or self.p2) and not self.p2 > self.p1:
            raise reject("p2", self.p2, f"> p1 ({self.p1})")


@MATCHERS.register("sgbm")
class SGBM(Matcher):
    """OpenCV semi-global block matching on the colour (or gray) pair."""

    name = "sgbm"
    Options = SGBMOptions
    options: SGBMOptions

    def check_width(self, width: int) -> None:
        """``max_disparity`` rounded up to 16, plus ``min_disparity``, must stay below ``width`` (and the base rule)."""
        super().check_width(width)
        _check_width(self.options.max_disparity, self.options.min_disparity, width)

    def runtime(self) -> MatcherRuntime:
        """OpenCV on the CPU: 16-bit integer costs and fixed-point disparities, OpenCV's thread pool."""
        return opencv_runtime()

    def _compute(self, left: np.ndarray, right: np.ndarray, hints: np.ndarray | None) -> np.ndarray:
        o = self.options
        nd = _check_width(o.max_disparity, o.min_disparity, left.shape[1])
        if left.ndim == 3 and left.shape[2] == 1:
            left, right = left[:, :, 0], right[:, :, 0]
        cn = 1 if left.ndim == 2 else left.shape[2]
        bs = o.block_size
        p1 = o.p1 or 8 * cn * bs * bs
        p2 = o.p2 or 32 * cn * bs * bs
        sgbm = cv2.StereoSGBM.create(
            minDisparity=o.min_disparity,
            numDisparities=nd,
            blockSize=bs,
            P1=p1,
            P2=p2,
            disp12MaxDiff=o.disp12_max_diff,
            preFilterCap=o.pre_filter_cap,
            uniquenessRatio=o.uniqueness,
            speckleWindowSize=o.speckle_window,
            speckleRange=o.speckle_range,
            mode=_SGBM_MODES[o.mode],
        )
        pad = 0 if o.left_band == "off" else o.min_disparity + nd
        raw = sgbm.compute(_pad_left(left, pad, o.left_band), _pad_left(right, pad, o.left_band))
        return _to_float(raw, o.min_disparity, pad)


@dataclass(frozen=True)
class BMOptions(MatcherOptions):
    """Options of the ``bm`` matcher (cv2.StereoBM, gray input).

    Attributes
    ----------
    block_size : int
        Odd SAD window in [5, 255], default 15.
    pre_filter : {"xsobel", "normalized"}
        Pre-filter: x-Sobel (default) or normalized response.
    pre_filter_size : int
        Odd size in [5, 255] of the normalized-response window (default 9).
    pre_filter_cap : int
        Pre-filter truncation in [1, 63] (default 31).
    min_disparity, uniqueness, texture_threshold : int
        Default 0, 15 (percent) and 10.
    speckle_window, speckle_range, disp12_max_diff : int
        As for ``sgbm`` (100, 2, 1).
    left_band : {"constant", "replicate", "off"}
        As for ``sgbm`` (default ``"replicate"``).
    """

    block_size: Annotated[int, Range(5, 255), Odd()] = 15
    pre_filter: Literal["xsobel", "normalized"] = "xsobel"
    pre_filter_size: Annotated[int, Range(5, 255), Odd()] = 9
    pre_filter_cap: Annotated[int, Range(1, 63)] = 31
    min_disparity: Annotated[int, Range(0)] = 0
    uniqueness: Annotated[int, Range(0)] = 15
    texture_threshold: Annotated[int, Range(0)] = 10
    speckle_window: Annotated[int, Range(0)] = 100
    speckle_range: Annotated[int, Range(0)] = 2
    disp12_max_diff: Annotated[int, Range(-1)] = 1
    left_band: Literal["constant", "replicate", "off"] = "replicate"


@MATCHERS.register("bm")
class BM(Matcher):
    """OpenCV block matching (SAD) on the gray pair."""

    name = "bm"
    Options = BMOptions
    options: BMOptions

    def check_width(self, width: int) -> None:
        """``max_disparity`` rounded up to 16, plus ``min_disparity``, must stay below ``width`` (and the base rule)."""
        super().check_width(width)
        _check_width(self.options.max_disparity, self.options.min_disparity, width)

    def runtime(self) -> MatcherRuntime:
        """OpenCV on the CPU: 16-bit integer costs and fixed-point disparities, OpenCV's thread pool."""
        return opencv_runtime()

    def _compute(self, left: np.ndarray, right: np.ndarray, hints: np.ndarray | None) -> np.ndarray:
        o = self.options
        nd = _check_width(o.max_disparity, o.min_disparity, left.shape[1])
        bm = cv2.StereoBM.create(numDisparities=nd, blockSize=o.block_size)
        bm.setPreFilterType(
            cv2.STEREO_BM_PREFILTER_XSOBEL if o.pre_filter == "xsobel" else cv2.STEREO_BM_PREFILTER_NORMALIZED_RESPONSE
        )
        bm.setPreFilterSize(o.pre_filter_size)
        bm.setPreFilterCap(o.pre_filter_cap)
        bm.setMinDisparity(o.min_disparity)
        bm.setUniquenessRatio(o.uniqueness)
        bm.setTextureThreshold(o.texture_threshold)
        bm.setSpeckleWindowSize(o.speckle_window)
        bm.setSpeckleRange(o.speckle_range)
        bm.setDisp12MaxDiff(o.disp12_max_diff)
        pad = 0 if o.left_band == "off" else o.min_disparity + nd
        gl = _pad_left(np.ascontiguousarray(to_gray(left)), pad, o.left_band)
        gr = _pad_left(np.ascontiguousarray(to_gray(right)), pad, o.left_band)
        return _to_float(bm.compute(gl, gr), o.min_disparity, pad)


__all__ = ["BM", "SGBM", "BMOptions", "SGBMOptions", "opencv_num_disparities"]
