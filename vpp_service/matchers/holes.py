"""Background interpolation of invalid disparities (the paper's evaluation protocol).

Before scoring, a matcher's holes are filled row by row: every run of NaN on a
row takes the *smaller* of its nearest valid neighbours on the left and on the
right (the background, as holes are mostly occlusions next to a foreground
edge). A run touching the image border takes its one neighbour. A row without
any valid pixel has nothing to interpolate from and is set to ``empty``
(NaN by default, so "no data" stays visible; pass ``empty=0.0`` for a map
with no NaN at all).
"""

from __future__ import annotations

import numpy as np

from vpp_service.matchers._holes import fill_rows
from vpp_service.matchers.base import check_disparity
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


__all__ = ["fill_holes"]
