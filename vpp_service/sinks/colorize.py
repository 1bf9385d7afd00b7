"""Disparity colourisation for visual sinks.

Maps disparities to RGB with OpenCV's perceptual *turbo* colour map (near =
large disparity = red, far = blue); invalid pixels (NaN, +/-inf, <= 0) are
black. The same range is used for dense maps and sparse points so both read
off one colour scale.
"""

from __future__ import annotations

import cv2
import numpy as np


def _check_array(values: object, name: str) -> np.ndarray:
    """Validate a real-valued ndarray and return it."""
    if not isinstance(values, np.ndarray):
        raise TypeError(f"{name}: must be a numpy ndarray, got {type(values).__name__}")
    if not (np.issubdtype(values.dtype, np.floating) or np.issubdtype(values.dtype, np.integer)):
        raise TypeError(f"{name}: must have a real numeric dtype, got {values.dtype}")
    return values


def disparity_range(*arrays: np.ndarray | None) -> tuple[float, float] | None:
    """Common ``(vmin, vmax)`` of the valid (finite, > 0) values of ``arrays``.

    Parameters
    ----------
    *arrays : ndarray or None
        Disparity arrays; ``None`` entries are skipped.

    Returns
    -------
    tuple of float or None
        ``(vmin, vmax)`` with ``vmax > vmin``, or None when no value is valid.

    Raises
    ------
    TypeError
        If an entry is neither None nor a real ndarray.
    """
    lo, hi = np.inf, -np.inf
    for i, a in enumerate(arrays):
        if a is None:
            continue
        arr = _check_array(a, f"arrays[{i}]")
        v = arr[np.isfinite(arr) & (arr > 0)] if arr.size else arr
        if v.size:
            lo, hi = min(lo, float(v.min())), max(hi, float(v.max()))
    if not np.isfinite(lo):
        return None
    if hi <= lo:
        hi = lo + 1.0
    return lo, hi


def _lut() -> np.ndarray:
    """256 x 3 uint8 RGB turbo lookup table."""
    ramp = np.arange(256, dtype=np.uint8).reshape(256, 1)
    bgr = cv2.applyColorMap(ramp, cv2.COLORMAP_TURBO).reshape(256, 3)
    return np.ascontiguousarray(bgr[:, ::-1])


_TURBO = _lut()


def colorize_disparity(disparity: np.ndarray, vmin: float | None = None, vmax: float | None = None) -> np.ndarray:
    """Colourise disparities with the turbo colour map.

    Parameters
    ----------
    disparity : ndarray
        Real array of any shape (usually H x W); NaN, inf and values <= 0 are
        invalid and become black.
    vmin, vmax : float or None
        Colour range; values are clipped to it. ``None`` takes the range of the
        valid values (see :func:`disparity_range`).

    Returns
    -------
    ndarray
        uint8 array of shape ``disparity.shape + (3,)``, RGB.

    Raises
    ------
    TypeError
        If ``disparity`` is not a real ndarray.
    ValueError
        If ``vmin``/``vmax`` are not finite or ``vmax <= vmin``.
    """
    disparity = _check_array(disparity, "disparity")
    if vmin is None or vmax is None:
        rng = disparity_range(disparity) or (0.0, 1.0)
        vmin = rng[0] if vmin is None else vmin
        vmax = rng[1] if vmax is None else vmax
    for name, v in (("vmin", vmin), ("vmax", vmax)):
        if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) or not np.isfinite(v):
            raise ValueError(f"{name}: must be a finite number, got {v!r}")
    if vmax <= vmin:
        raise ValueError(f"vmax: must be > vmin ({vmin}), got {vmax}")
    d = disparity.astype(np.float32, copy=False)
    valid = np.isfinite(d) & (d > 0)
    with np.errstate(invalid="ignore"):
        t = (np.where(valid, d, vmin) - np.float32(vmin)) * np.float32(255.0 / (vmax - vmin))
    idx = np.clip(np.rint(t), 0, 255).astype(np.uint8)
    out = _TURBO[idx]
    out[~valid] = 0
    return out


__all__ = ["colorize_disparity", "disparity_range"]
