"""Speckle filter: invalidate small connected blobs of disparity (rSGM's outlier removal).

The paper runs its census SGM "applying left-right check and a speckle filter to
remove outliers, then filling holes with background interpolation". Wrong
matches in occluded and textureless areas form small islands whose disparity
differs from their surroundings; removing them lets hole filling put the
background there instead.
"""

from __future__ import annotations

import cv2
import numpy as np

from vpp_service.matchers.base import check_array

#: Fixed-point scale used for region growing (OpenCV works on int16).
SUBPIXEL_SCALE = 16


def remove_speckles(disparity: np.ndarray, max_size: int = 200, max_diff: float = 2.0) -> np.ndarray:
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

    Returns
    -------
    ndarray
        H x W float32, NaN where invalid or removed.

    Raises
    ------
    TypeError
        If ``disparity`` is not a float32 array.
    ValueError
        If it is not 2-D, or ``max_size`` / ``max_diff`` are out of range.
    """
    check_array(disparity, "disparity", (np.float32,), 2, "a 2-D (H x W) map", contiguous=False)
    if isinstance(max_size, bool) or not isinstance(max_size, (int, np.integer)) or max_size < 0:
        raise ValueError(f"max_size must be an integer >= 0, got {max_size!r}")
    if not (np.isfinite(max_diff) and max_diff >= 0):
        raise ValueError(f"max_diff must be a finite number >= 0, got {max_diff!r}")
    out = disparity.copy()
    if max_size == 0:
        return out
    valid = np.isfinite(disparity)
    if np.any(np.abs(disparity[valid]) >= 32767 / SUBPIXEL_SCALE):
        raise ValueError("disparity values must be below 2047 px for the speckle filter")
    fixed = np.full(disparity.shape, -SUBPIXEL_SCALE, np.int16)
    fixed[valid] = np.rint(disparity[valid] * SUBPIXEL_SCALE).astype(np.int16)
    cv2.filterSpeckles(fixed, -SUBPIXEL_SCALE, int(max_size), round(max_diff * SUBPIXEL_SCALE))
    out[(fixed == -SUBPIXEL_SCALE) & valid] = np.nan
    return out


__all__ = ["SUBPIXEL_SCALE", "remove_speckles"]
