"""Filling invalid disparities along rows.

:func:`fill_holes` is the background interpolation of the paper's evaluation
protocol. Before scoring, a matcher's holes are filled row by row: every run of NaN on a
row takes the *smaller* of its nearest valid neighbours on the left and on the
right (the background, as holes are mostly occlusions next to a foreground
edge). A run touching the image border takes its one neighbour. A row without
any valid pixel has nothing to interpolate from and is set to ``empty``
(NaN by default, so "no data" stays visible; pass ``empty=0.0`` for a map
with no NaN at all).

:func:`fill_short_gaps` is a matcher post-processing step (SGM's gap
interpolation): only short gaps *inside* a row are closed, so that a few
rejected pixels inside a surface do not split it (the median and speckle
filter then see one region), while occlusions and borders stay holes.
"""

from __future__ import annotations

import math

import numpy as np

from vpp_service.matchers._holes import fill_gap_rows, fill_rows
from vpp_service.matchers.inputs import check_disparity
from vpp_service.threads import resolve_threads


def fill_holes(disparity: np.ndarray, empty: float = float("nan"), threads: int | None = None) -> np.ndarray:
    """Fill NaN holes of a disparity map with background interpolation along rows.

    Parameters
    ----------
    disparity : ndarray
        H x W float disparity, NaN = hole. Not modified.
    empty : float, optional
        Value for rows with no valid pixel at all (NaN by default; e.g. 0.0).
    threads : int or None, optional
        OpenMP threads (None = :func:`~vpp_service.threads.default_threads`).

    Returns
    -------
    ndarray
        New H x W float32 map: valid pixels copied, each NaN run replaced by
        ``min(left neighbour, right neighbour)`` (one side at a border).

    Raises
    ------
    TypeError
        Not a numpy float array.
    ValueError
        Not 2-D, empty, or containing +-inf.

    Examples
    --------
    >>> fill_holes(np.array([[np.nan, 3, np.nan, np.nan, 5, 1, np.nan]], np.float32))
    array([[3., 3., 3., 3., 5., 1., 1.]], dtype=float32)
    """
    src = check_disparity(disparity, "disparity", convert=True)
    if not isinstance(empty, (int, float)) or np.isinf(empty):
        raise ValueError(f"empty must be a finite number or NaN, got {empty!r}")
    out = np.empty_like(src)
    fill_rows(src, out, float(empty), resolve_threads(threads))
    return out


#: Default largest step between a gap's ends (pixels) for linear filling (:func:`fill_short_gaps`).
GAP_STEP = 2.0


def fill_short_gaps(
    disparity: np.ndarray, max_gap: int = 4, max_step: float = GAP_STEP, threads: int | None = None
) -> np.ndarray:
    """Close short interior gaps of a disparity map along rows.

    A gap is a run of NaN on a row with a valid pixel on both sides. Gaps of at
    most ``max_gap`` pixels are filled: linearly between the two ends when they
    differ by at most ``max_step`` pixels (one surface), otherwise with the
    smaller end (the background, as at an occlusion). Longer gaps and runs
    touching the image border are left NaN.

    Parameters
    ----------
    disparity : ndarray
        H x W float disparity, NaN = invalid. Not modified.
    max_gap : int, optional
        Longest gap (pixels) that is filled; 0 fills nothing.
    max_step : float, optional
        Largest difference (pixels) between the ends for linear interpolation.
    threads : int or None, optional
        OpenMP threads (None = :func:`~vpp_service.threads.default_threads`).

    Returns
    -------
    ndarray
        New H x W float32 map.

    Raises
    ------
    TypeError
        Not a numpy float array.
    ValueError
        Not 2-D, empty, containing +-inf, ``max_gap`` not an integer >= 0 or
        ``max_step`` not a finite number >= 0.

    Examples
    --------
    >>> fill_short_gaps(np.array([[2, np.nan, 4, np.nan, 9, np.nan, np.nan, np.nan, 1]], np.float32), max_gap=2)
    array([[ 2.,  3.,  4.,  4.,  9., nan, nan, nan,  1.]], dtype=float32)
    """
    src = check_disparity(disparity, "disparity", convert=True)
    if isinstance(max_gap, bool) or not isinstance(max_gap, (int, np.integer)) or max_gap < 0:
        raise ValueError(f"max_gap must be an integer >= 0, got {max_gap!r}")
    if (
        isinstance(max_step, bool)
        or not isinstance(max_step, (int, float))
        or not math.isfinite(max_step)
        or max_step < 0
    ):
        raise ValueError(f"max_step must be a finite number >= 0, got {max_step!r}")
    out = np.empty_like(src)
    fill_gap_rows(src, out, int(max_gap), float(max_step), resolve_threads(threads))
    return out


__all__ = ["fill_holes", "fill_short_gaps"]
