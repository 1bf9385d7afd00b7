"""The depth range the service answers for: ``[depth_clip]`` ``min_depth_m`` / ``max_depth_m``.

Depth is ``Z = f * baseline / (d + doffs)``: a disparity near zero is a depth
far beyond anything the rig can measure (SGBM's 1/16 px step alone is 6 km on
a KITTI rig), and the matcher cannot find a disparity beyond its range. So a
disparity counts as valid only inside ``[d_lo, d_hi]``:

``d_lo`` (sets the largest depth, ``max_depth = f * baseline / (d_lo + doffs)``)
    ``max_depth_m`` > 0 on a calibrated frame: ``f * baseline / max_depth_m - doffs``.
    Default (0, or no calibration): ``max(min_disparity, 1)`` px, the smallest
    disparity worth a depth: one pixel, or the matcher's own lowest hypothesis.
``d_hi`` (sets the smallest depth, ``min_depth = f * baseline / (d_hi + doffs)``)
    ``min_depth_m`` > 0 on a calibrated frame: ``f * baseline / min_depth_m - doffs``.
    Default: ``min_disparity + max_disparity``, the top of the matcher's range
    (what it searched; nothing nearer can be matched).

A disparity that is not finite, not > 0 or outside ``[d_lo, d_hi]`` becomes NaN
(:meth:`DepthClip.apply`) before depth, metrics and every sink see it, so all
outputs agree: NaN in the float outputs (disparity and depth, ``.npy``,
``.pfm``'s ``+inf``, Zenoh, ROS 2), 0 in the 16-bit PNG (every valid disparity
is > 0, so it encodes as at least 1), no point in Rerun's 3-D view.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated

import numpy as np

from vpp_service.frame import Calibration
from vpp_service.matchers.base import Matcher
from vpp_service.settings import Options, Range, reject

#: The smallest disparity (px) worth a depth unless ``max_depth_m`` says otherwise.
MIN_DISPARITY_PX = 1.0


@dataclass(frozen=True)
class DepthClip(Options):
    """``[depth_clip]``: the depth range of every output (see the module docstring).

    Attributes
    ----------
    min_depth_m : float
        Nearest valid depth in metres; 0 (default): the top of the matcher's range.
    max_depth_m : float
        Farthest valid depth in metres; 0 (default): the depth of ``max(min_disparity, 1)`` px.
    """

    min_depth_m: Annotated[float, Range(0.0)] = 0.0
    max_depth_m: Annotated[float, Range(0.0)] = 0.0

    def cross_check(self) -> None:
        """A set ``max_depth_m`` lies beyond ``min_depth_m``."""
        if 0 < self.max_depth_m <= self.min_depth_m:
            raise reject("max_depth_m", self.max_depth_m, f"> min_depth_m ({self.min_depth_m}) or 0")

    def disparity_bounds(self, matcher: Matcher, calib: Calibration | None) -> tuple[float, float]:
        """``(d_lo, d_hi)`` in pixels for a frame matched by ``matcher`` with ``calib``.

        The metric bounds need a calibration; without one (or at 0) the defaults from the matcher apply.
        """
        o = matcher.options
        low = float(getattr(o, "min_disparity", 0))
        d_lo, d_hi = max(low, MIN_DISPARITY_PX), low + float(o.max_disparity)
        if calib is not None:
            fb = calib.f * calib.baseline
            if self.max_depth_m > 0:
                d_lo = fb / self.max_depth_m - calib.doffs
            if self.min_depth_m > 0:
                d_hi = fb / self.min_depth_m - calib.doffs
        return d_lo, d_hi

    def depth_bounds(self, matcher: Matcher, calib: Calibration) -> tuple[float, float]:
        """``(min_depth, max_depth)`` in metres for a frame matched by ``matcher`` with ``calib``.

        ``max_depth`` is ``inf`` when ``d_lo + doffs <= 0`` (no finite bound).
        """
        d_lo, d_hi = self.disparity_bounds(matcher, calib)
        fb = calib.f * calib.baseline
        far = fb / (d_lo + calib.doffs) if d_lo + calib.doffs > 0 else math.inf
        return fb / (d_hi + calib.doffs), far

    def apply(self, disparity: np.ndarray, matcher: Matcher, calib: Calibration | None) -> np.ndarray:
        """``disparity`` with every pixel outside the range (or not finite, or <= 0) set to NaN.

        Parameters
        ----------
        disparity : ndarray
            H x W float32 disparity from ``matcher``; changed in place when writeable.
        matcher : Matcher
            The matcher that produced it (its ``min_disparity``/``max_disparity`` give the defaults).
        calib : Calibration or None
            The frame's calibration (the metric bounds need it).

        Returns
        -------
        ndarray
            The clipped map (``disparity`` itself when it was writeable).
        """
        d_lo, d_hi = self.disparity_bounds(matcher, calib)
        floor = 0.0 if calib is None else max(0.0, -calib.doffs)  # d > 0 (PNG's 0), and d + doffs > 0 (a depth)
        lo = np.float32(d_lo) if d_lo > floor else np.nextafter(np.float32(floor), np.float32(np.inf))
        with np.errstate(invalid="ignore"):
            drop = ~((disparity >= lo) & (disparity <= np.float32(d_hi)))  # NaN compares false: dropped
        out = disparity if disparity.flags.writeable else disparity.copy()
        out[drop] = np.nan
        return out


__all__ = ["MIN_DISPARITY_PX", "DepthClip"]
