"""The disparity range from the scene: ``max_disparity = "auto"``.

A fixed ``max_disparity`` searches the same range on every frame: too small
and near objects are lost, too large and every pixel pays for hypotheses that
no point of the scene needs (and the matcher's invalid left band grows).
:class:`DisparityRange` derives ``D`` per frame instead:

* **From calibration** when ``min_depth_m`` > 0 and the frame is calibrated:
  the disparity of the nearest depth of interest, ``f * baseline / min_depth_m
  - doffs``.
* **Else from the frame's sparse points**: their largest disparity plus
  ``margin`` pixels.
* **Else** (neither) the range in use, or ``limit`` on the first frame.

The wanted value is rounded **up** to a multiple of 16, at least 16, and
clamped to ``limit`` and to the largest multiple of 16 below the image width.

Matchers keep buffers sized by ``D`` between calls, so the range must not
churn: it **grows at once** (a near object needs it now) but **shrinks only**
after ``shrink_after`` consecutive frames all wanted at least 32 less (two
steps of 16), and then to the largest of those frames' wants.
:class:`MatcherCache` keeps the few matcher instances built for the ranges in
use (least recently used evicted).
"""

from __future__ import annotations

import logging
import math
from collections import OrderedDict
from dataclasses import dataclass, replace
from typing import Annotated

import numpy as np

from vpp_service.frame import Calibration
from vpp_service.matchers.base import Matcher
from vpp_service.settings import MultipleOf, Options, Range

log = logging.getLogger(__name__)

#: Ranges are multiples of this (OpenCV's numDisparities step).
STEP = 16
#: A want this far below the range in use counts towards shrinking.
SHRINK_GAP = 2 * STEP


@dataclass(frozen=True)
class AutoRangeOptions(Options):
    """How ``max_disparity = "auto"`` picks the range (config ``[matcher.auto_range]``).

    Attributes
    ----------
    min_depth_m : float
        Nearest depth of interest in metres; > 0: ``D`` from the calibration
        (``f * baseline / min_depth_m - doffs``) on calibrated frames. 0
        (default): from the sparse points.
    margin : int
        Pixels added to the largest sparse disparity (default 16).
    limit : int
        Largest range ever used, a multiple of 16 in [16, 4096] (default 256).
    shrink_after : int
        Consecutive frames that must all want at least 32 less before the
        range shrinks (default 30; >= 1).
    """

    min_depth_m: Annotated[float, Range(0.0)] = 0.0
    margin: Annotated[int, Range(0, 4096)] = 16
    limit: Annotated[int, Range(STEP, 4096), MultipleOf(STEP)] = 256
    shrink_after: Annotated[int, Range(1, 1_000_000)] = 30


def round_range(wanted: float, width: int, limit: int) -> int:
    """``wanted`` rounded up to a multiple of 16, at least 16, at most ``limit`` and below ``width``.

    Raises
    ------
    ValueError
        ``width`` <= 16: no multiple of 16 lies below it.
    """
    below = (int(width) - 1) // STEP * STEP
    if below < STEP:
        raise ValueError(f"image width {width} leaves no disparity range (needs > {STEP} px)")
    d = STEP * max(1, math.ceil(wanted / STEP)) if math.isfinite(wanted) else limit
    return int(min(d, limit, below))


def wanted_range(sparse: np.ndarray | None, calib: Calibration | None, options: AutoRangeOptions) -> float | None:
    """The range one frame asks for before rounding, or None when it carries nothing to derive it from.

    Parameters
    ----------
    sparse : ndarray or None
        H x W sparse disparity (NaN or <= 0 = no point).
    calib : Calibration or None
        The frame's calibration.
    options : AutoRangeOptions
        ``min_depth_m`` and ``margin``.
    """
    if options.min_depth_m > 0 and calib is not None:
        return calib.f * calib.baseline / options.min_depth_m - calib.doffs
    if sparse is None:
        return None
    with np.errstate(invalid="ignore"):
        top = np.nanmax(sparse, initial=0.0)
    if not top > 0 or not math.isfinite(top):
        return None
    return float(top) + options.margin


class DisparityRange:
    """The range to use per frame, with growth at once and hysteresis on shrinking (see the module docstring)."""

    def __init__(self, options: AutoRangeOptions | None = None) -> None:
        self.options = options or AutoRangeOptions()
        #: The range in use (None before the first frame).
        self.current: int | None = None
        self._low = 0  # consecutive frames that wanted at least SHRINK_GAP less
        self._low_max = 0

    def update(self, sparse: np.ndarray | None, calib: Calibration | None, width: int) -> int:
        """The range for a frame of ``width`` columns with these sparse points and calibration.

        Raises
        ------
        ValueError
            ``width`` <= 16.
        """
        o = self.options
        raw = wanted_range(sparse, calib, o)
        if raw is None:  # nothing to go by: keep the range in use
            want = round_range(self.current if self.current is not None else o.limit, width, o.limit)
        else:
            want = round_range(raw, width, o.limit)
        cur = self.current
        if cur is None or want > cur:
            self._set(want)
        elif want <= cur - SHRINK_GAP:
            self._low += 1
            self._low_max = max(self._low_max, want)
            if self._low >= o.shrink_after:
                self._set(self._low_max)
        else:
            self._low, self._low_max = 0, 0
        assert self.current is not None
        return round_range(self.current, width, o.limit)  # a narrower frame than the last ones

    def _set(self, d: int) -> None:
        if d != self.current:
            log.info("disparity range: %s -> %d", self.current, d)
        self.current = d
        self._low, self._low_max = 0, 0


class MatcherCache:
    """Matcher instances by ``max_disparity``, built from a template, the ``size`` most recently used kept.

    Parameters
    ----------
    template : Matcher
        Its type and options (``max_disparity`` replaced) build each instance.
    size : int
        Instances kept (>= 1; default 2: the range in use and the one before, each may hold large buffers).
    """

    def __init__(self, template: Matcher, size: int = 2) -> None:
        if size < 1:
            raise ValueError(f"size must be >= 1, got {size}")
        self.template = template
        self.size = size
        self._items: OrderedDict[int, Matcher] = OrderedDict()
        #: Instances built so far.
        self.built = 0

    def get(self, max_disparity: int) -> Matcher:
        """The matcher for ``max_disparity`` (built on first use)."""
        m = self._items.get(max_disparity)
        if m is None:
            t = self.template
            m = (
                t
                if t.options.max_disparity == max_disparity
                else type(t)(replace(t.options, max_disparity=max_disparity))
            )
            self.built += 1
            self._items[max_disparity] = m
            while len(self._items) > self.size:
                self._items.popitem(last=False)
        else:
            self._items.move_to_end(max_disparity)
        return m


__all__ = ["AutoRangeOptions", "DisparityRange", "MatcherCache", "round_range", "wanted_range"]
