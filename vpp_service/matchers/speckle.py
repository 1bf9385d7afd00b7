"""Speckle filter: invalidate small connected blobs of disparity (rSGM's outlier removal).

The paper runs its census SGM "applying left-right check and a speckle filter to
remove outliers, then filling holes with background interpolation". Wrong
matches in occluded and textureless areas form small islands whose disparity
differs from their surroundings; removing them lets hole filling put the
background there instead.

The regions are those of OpenCV's ``filterSpeckles`` (4-connected, disparities
compared at 1/16 px); the kernel (``_speckle.h``) finds them by union-find on
row strips in parallel.
"""

from __future__ import annotations

import numpy as np

from vpp_service.matchers._speckle import speckle_filter
from vpp_service.matchers.inputs import check_array
from vpp_service.threads import resolve_threads

#: Fixed-point scale of the disparity comparison (OpenCV's ``filterSpeckles`` works on 1/16 px int16).
SUBPIXEL_SCALE = 16


def remove_speckles(
    disparity: np.ndarray, max_size: int = 200, max_diff: float = 2.0, threads: int | None = None
) -> np.ndarray:
    """Set to NaN every 4-connected region of at most ``max_size`` pixels.

    Two 4-neighbours belong to one region when their disparities differ by at
    most ``max_diff`` pixels (compared at 1/16 px, OpenCV's
    ``filterSpeckles``). Valid values that survive are returned unchanged
    (full float precision).

    Parameters
    ----------
    disparity : ndarray
        H x W float32 disparity, NaN = invalid. Not modified.
    max_size : int
        Largest region size (pixels) that is removed; 0 disables the filter.
    max_diff : float
        Largest disparity step inside a region, pixels (>= 0).
    threads : int or None, optional
        OpenMP threads (None = :func:`~vpp_service.threads.default_threads`).

    Returns
    -------
    ndarray
        H x W float32, NaN where invalid or removed.

    Raises
    ------
    TypeError
        If ``disparity`` is not a float32 array.
    ValueError
        If it is not 2-D, ``max_size`` / ``max_diff`` / ``threads`` are out of
        range, or a finite disparity is at or beyond 2047.9375 px in magnitude
        (1/16 px must fit int16, as in OpenCV).
    """
    check_array(disparity, "disparity", (np.float32,), 2, "a 2-D (H x W) map", contiguous=False)
    if isinstance(max_size, bool) or not isinstance(max_size, (int, np.integer)) or max_size < 0:
        raise ValueError(f"max_size must be an integer >= 0, got {max_size!r}")
    if not (np.isfinite(max_diff) and max_diff >= 0):
        raise ValueError(f"max_diff must be a finite number >= 0, got {max_diff!r}")
    if max_size == 0:
        return disparity.copy()
    h, w = disparity.shape
    if h * w >= 2**31:
        raise ValueError(f"disparity has {h * w} pixels, the speckle filter takes fewer than 2**31")
    src = np.ascontiguousarray(disparity)
    out = np.empty_like(src)
    scratch = np.empty(3 * h * w, np.int32)
    size = min(int(max_size), h * w)  # larger sizes remove the same regions
    diff16 = min(round(max_diff * SUBPIXEL_SCALE), 2**31 - 1)
    if not speckle_filter(src, out, scratch, size, diff16, resolve_threads(threads)):
        raise ValueError("disparity values must be below 2047 px for the speckle filter")
    return out


__all__ = ["SUBPIXEL_SCALE", "remove_speckles"]
