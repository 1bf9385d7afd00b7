"""The see-through filter: sparse points that a nearer surface hides from the left camera.

A LiDAR mounted beside the camera sees past foreground edges that the camera
cannot see past. Projected into the left image, such a return lands on a
foreground pixel with the depth of the background behind it: a
*see-through point*. VPP would paint a wrong correspondence there with full
confidence, so these points are removed before VPP.

Rule: a point of disparity ``d`` is dropped when its image neighbourhood, a
``window_w`` x ``window_h`` window centred on it (clipped at the image border),
holds *clearly nearer* points (disparity ``> max(d * (1 + margin), d + min_gap)``)
on two opposite sides: both in the window's columns left of it and in those
right of it, or both in the rows above it and in the rows below it. A
see-through point lies *inside* the foreground that hides it, among the
foreground's own returns; a background point that the camera does see, next to
a foreground edge, has nearer points on one side only and is kept. The
relative ``margin`` separates surfaces at different depths; the absolute
``min_gap`` (pixels) keeps a slanted surface (a road seen at a grazing angle,
whose disparity grows row by row) from filtering itself. A tie (exactly the
threshold) keeps the point. Inputs: 0, negative, NaN or infinite values are
"no point".

The filter is a compiled kernel (one thread, no GIL; an AVX2 build where
:mod:`vpp_service.vpp.backend` selects one): the window maxima of the rows
above and below each row by van Herk / Gil-Werman blocks, then per row the
maxima over the window's columns by doubling, every loop vectorised; about
0.7 ms for a 120k-point scan at KITTI size, one thread
(``benchmarks/bench_see_through.py``, ``docs/results.md``).

When it runs is :class:`DepthFilter`'s ``mode``: ``auto`` (the default) filters
the frames whose points may see through, which the frame declares with
``meta["lidar_like"] = True`` (see :mod:`vpp_service.frame`); ``see-through``
filters every frame; ``none`` never filters.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import ModuleType
from typing import Annotated, Literal

import numpy as np

from vpp_service.settings import Odd, Options, Range
from vpp_service.vpp import _see_through as portable
from vpp_service.vpp import backend
from vpp_service.vpp._validate import as_disparity


def avx2_build() -> ModuleType | None:
    """The AVX2 build of the kernel when :mod:`vpp_service.vpp.backend` runs AVX2 and it was built, else None."""
    if backend.avx2_build() is None:
        return None
    try:
        from vpp_service.vpp import _see_through_avx2
    except ImportError:  # not built (non-x86 platform or a compiler without -mavx2)
        return None
    return _see_through_avx2


#: The kernel build in use: AVX2 exactly when the VPP kernel runs its AVX2 build.
_k: ModuleType = (avx2_build() or portable) if backend.AVX2 else portable

#: Values of :attr:`DepthFilter.mode`.
FILTER_MODES = ("auto", "see-through", "none")

#: The frame-meta key by which a frame declares points from a sensor displaced from the left camera.
LIDAR_LIKE = "lidar_like"

#: Defaults of the filter (tuned in ``benchmarks/bench_see_through.py``, see ``docs/results.md``).
DEFAULT_WINDOW_W = 5
DEFAULT_WINDOW_H = 11
DEFAULT_MARGIN = 0.3
DEFAULT_MIN_GAP = 1.0


def _check_window(name: str, v: object) -> int:
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
        raise TypeError(f"{name}: must be an odd integer >= 1, got {v!r}")
    if v < 1 or v % 2 == 0 or v > 1001:
        raise ValueError(f"{name}: must be an odd integer in [1, 1001], got {v!r}")
    return int(v)


def _check_non_negative(name: str, v: object) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)):
        raise TypeError(f"{name}: must be a finite number >= 0, got {v!r}")
    if not math.isfinite(v) or v < 0:
        raise ValueError(f"{name}: must be a finite number >= 0, got {v!r}")
    return float(v)


def filter_see_through(
    disparity: np.ndarray,
    window_w: int = DEFAULT_WINDOW_W,
    window_h: int = DEFAULT_WINDOW_H,
    margin: float = DEFAULT_MARGIN,
    min_gap: float = DEFAULT_MIN_GAP,
) -> tuple[np.ndarray, int]:
    """Drop the points that have clearly nearer points on two opposite sides in their neighbourhood.

    Parameters
    ----------
    disparity : ndarray
        H x W float32/float64 sparse disparity; NaN, <= 0 or infinite = no point. Not modified.
    window_w, window_h : int
        Window width and height (odd, pixels), centred on each point.
    margin : float
        Relative margin (>= 0): a neighbour is clearly nearer above ``d * (1 + margin)``.
    min_gap : float
        Absolute margin (pixels, >= 0): ... and above ``d + min_gap``.

    Returns
    -------
    (ndarray, int)
        A new H x W float32 map with the kept points (NaN elsewhere, also where
        the input held a non-point such as 0 or inf) and the number of dropped points.

    Raises
    ------
    TypeError
        Not a numpy float32/float64 array, or a window / margin of the wrong type.
    ValueError
        Not 2-D, empty, an even or non-positive window, a negative or non-finite margin.

    Examples
    --------
    >>> d = np.array([[30.0, 10.0, 30.0, 10.0]], np.float32)
    >>> filter_see_through(d, window_w=3, window_h=1)
    (array([[30., nan, 30., 10.]], dtype=float32), 1)
    """
    src = as_disparity("disparity", disparity)
    rx = _check_window("window_w", window_w) // 2
    ry = _check_window("window_h", window_h) // 2
    m = _check_non_negative("margin", margin)
    gap = _check_non_negative("min_gap", min_gap)
    out = np.empty_like(src)
    dropped = int(_k.see_through_rows(src, out, rx, ry, m, gap))
    if dropped < 0:
        raise MemoryError("filter_see_through: cannot allocate the row buffer")
    return out, int(dropped)


@dataclass(frozen=True)
class DepthFilter(Options):
    """Which frames' sparse points are filtered before VPP, and how (the ``[depth_filter]`` settings).

    Attributes
    ----------
    mode : {"auto", "see-through", "none"}
        ``auto`` (default): filter the frames that declare LiDAR-like points
        (``meta["lidar_like"]``); ``see-through``: filter every frame;
        ``none``: never.
    window_w, window_h : int
        Window of :func:`filter_see_through` (odd, pixels). Default 5 x 11.
    margin : float
        Relative margin of :func:`filter_see_through`. Default 0.3.
    min_gap : float
        Absolute margin (pixels) of :func:`filter_see_through`. Default 1.
    """

    mode: Literal["auto", "see-through", "none"] = "auto"
    window_w: Annotated[int, Range(1, 1001), Odd()] = DEFAULT_WINDOW_W
    window_h: Annotated[int, Range(1, 1001), Odd()] = DEFAULT_WINDOW_H
    margin: Annotated[float, Range(0.0)] = DEFAULT_MARGIN
    min_gap: Annotated[float, Range(0.0)] = DEFAULT_MIN_GAP

    def applies(self, meta: dict[str, object]) -> bool:
        """Whether a frame with this ``meta`` is filtered (see ``mode``)."""
        if self.mode == "none":
            return False
        return self.mode == "see-through" or meta.get(LIDAR_LIKE) is True

    def __call__(self, disparity: np.ndarray) -> tuple[np.ndarray, int]:
        """:func:`filter_see_through` with these settings."""
        return filter_see_through(disparity, self.window_w, self.window_h, self.margin, self.min_gap)


__all__ = ["FILTER_MODES", "LIDAR_LIKE", "DepthFilter", "filter_see_through"]
