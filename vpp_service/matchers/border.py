"""Rejecting matches that land on the border of the other view.

A left pixel ``x`` with disparity ``d`` is matched with the right pixel
``x_r = x - round(d)``. Within a few columns of the right image's border the
matching window is clamped (the census codes there describe replicated border
pixels) and the disparity search is truncated, so a left pixel whose true match
lies *outside* the right image (the left band ``x < d``) is often given a wrong
disparity that maps onto the first right columns, and both views agree on it.
Background interpolation then copies that wrong value into the whole band to
its left. Rejecting matches whose ``x_r`` is within ``margin`` columns of a
border of the right image removes them; a sensible margin is the matching
window's radius (2 for the 5 x 5 census).
"""

from __future__ import annotations

import numpy as np

from vpp_service.matchers.inputs import check_disparity


def reject_border_matches(disparity: np.ndarray, margin: int = 2) -> np.ndarray:
    """Invalidate left disparities whose match lies within ``margin`` columns of the right image's border.

    Keeps ``d = disparity(y, x)`` iff ``x_r = x - floor(d + 0.5)`` (the rounding of
    the left-right check) satisfies ``margin <= x_r <= W - 1 - margin``.

    Parameters
    ----------
    disparity : ndarray
        H x W float left disparity, NaN = invalid. Not modified.
    margin : int, optional
        Border width in columns (>= 0); 0 only rejects matches outside the image.

    Returns
    -------
    ndarray
        New H x W float32 map, NaN where rejected or already invalid.

    Raises
    ------
    TypeError
        Not a numpy float array.
    ValueError
        Not 2-D, empty, containing +-inf, or ``margin`` not an integer >= 0.

    Examples
    --------
    >>> reject_border_matches(np.array([[0.0, 1.0, 1.0, 1.4, 4.6, 0.0]], np.float32), margin=1)
    array([[nan, nan, 1. , 1.4, nan, nan]], dtype=float32)
    """
    src = check_disparity(disparity, "disparity", convert=True)
    if isinstance(margin, bool) or not isinstance(margin, (int, np.integer)) or margin < 0:
        raise ValueError(f"margin must be an integer >= 0, got {margin!r}")
    w = src.shape[1]
    x = np.arange(w, dtype=np.float32)
    # floor(d + 0.5) <= x - margin  <=>  d + 0.5 < x - margin + 1 (and likewise for the right
    # border); d + 0.5 is exact in float32 for |d| < 2**22, and NaN fails both comparisons
    v = src + np.float32(0.5)
    keep = (v < x - margin + 1) & (v >= x - (w - 1 - margin))
    return np.where(keep, src, np.float32(np.nan))


__all__ = ["reject_border_matches"]
