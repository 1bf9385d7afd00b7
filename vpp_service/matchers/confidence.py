"""Per-pixel confidence of a disparity map: the left-right check of a second pass, and ``min_confidence``.

Every matcher can give a confidence map beside its disparity
(:meth:`Matcher.compute_with_confidence <vpp_service.matchers.base.Matcher.compute_with_confidence>`):
H x W float32 in ``[0, 1]``, 0 where the matcher gives no answer. Census-SGM
computes it from its own cost curve and right view in the same pass (peak ratio
times left-right agreement, see :class:`~vpp_service.matchers.census_sgm.CensusSGM`);
every other matcher (SGBM, BM, the networks) gets the left-right agreement of a
second pass on the mirrored pair (:func:`right_view`), which doubles its
matching time, so it runs only when a confidence is asked for:

``confidence = max(0, 1 - |d_L(x) - d_R(x - round(d_L(x)))| / LR_SPAN)``

0 where ``d_L`` or ``d_R`` is NaN or the right pixel lies outside the image: a
pixel whose two views agree exactly has 1, one pixel of disagreement 0.5, two
or more 0.

``min_confidence`` (:func:`apply_min_confidence`) turns the pixels below it into
holes (NaN), before hole filling, depth and every output.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

#: The left-right disagreement (pixels) at which the two-pass confidence reaches 0.
LR_SPAN = 2.0


def right_view(
    compute: Callable[[np.ndarray, np.ndarray], np.ndarray], left: np.ndarray, right: np.ndarray
) -> np.ndarray:
    """The disparity of the right view, from a matcher of left views run on the mirrored, swapped pair.

    Mirrored left to right, the right image is the left view of a stereo pair whose
    right view is the mirrored left image; its disparity, mirrored back, is the
    right view's (``x_left = x_right + d``).

    Parameters
    ----------
    compute : callable
        ``compute(left, right)``: H x W float32 disparity of the left view (NaN = none).
    left, right : ndarray
        The rectified pair (H x W or H x W x C uint8).

    Returns
    -------
    ndarray
        H x W float32 disparity of the right view, NaN = none.
    """
    mirrored = compute(np.ascontiguousarray(right[:, ::-1]), np.ascontiguousarray(left[:, ::-1]))
    return np.ascontiguousarray(np.asarray(mirrored, dtype=np.float32)[:, ::-1])


def lr_confidence(disp_left: np.ndarray, disp_right: np.ndarray, span: float = LR_SPAN) -> np.ndarray:
    """``max(0, 1 - |d_L(x) - d_R(x - round(d_L(x)))| / span)``; 0 where either is NaN or ``x_r`` is outside.

    ``round`` is ``floor(d + 0.5)``, as the census-SGM left-right check.

    Parameters
    ----------
    disp_left, disp_right : ndarray
        H x W float32 disparities of the left and the right view.
    span : float
        The disagreement (pixels, > 0) at which the confidence reaches 0.

    Returns
    -------
    ndarray
        H x W float32 in [0, 1].
    """
    if disp_left.shape != disp_right.shape or disp_left.ndim != 2:
        raise ValueError(
            f"disp_left and disp_right must be H x W of one shape, got {disp_left.shape}, {disp_right.shape}"
        )
    if not span > 0:
        raise ValueError(f"span must be > 0, got {span}")
    h, w = disp_left.shape
    dl = disp_left.astype(np.float64)
    ok = np.isfinite(dl)
    xr = np.arange(w)[None, :] - np.floor(np.where(ok, dl, 0.0) + 0.5)
    ok &= (xr >= 0) & (xr < w)
    xi = np.clip(xr, 0, w - 1).astype(np.intp)
    dr = disp_right.astype(np.float64)[np.arange(h)[:, None], xi]
    ok &= np.isfinite(dr)
    conf = np.where(ok, 1.0 - np.abs(np.where(ok, dl - dr, 0.0)) / span, 0.0)
    return np.clip(conf, 0.0, 1.0).astype(np.float32)


def check_min_confidence(value: float) -> None:
    """Raise ValueError unless ``value`` is a finite number in [0, 1] (0 = off)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value <= 1:
        raise ValueError(f"min_confidence must be a number in [0, 1] (0 = off), got {value!r}")


def apply_min_confidence(disparity: np.ndarray, confidence: np.ndarray, min_confidence: float) -> np.ndarray:
    """Holes (NaN) where ``confidence < min_confidence``, and confidence 0 wherever the disparity is NaN.

    Both maps are changed in place (the disparity when writeable, else a copy is
    returned); ``min_confidence`` 0 only zeroes the confidence of the holes.

    Returns
    -------
    ndarray
        The disparity with the new holes.
    """
    if min_confidence > 0:
        low = confidence < np.float32(min_confidence)
        if low.any():
            if not disparity.flags.writeable:
                disparity = disparity.copy()
            disparity[low] = np.nan
    confidence[np.isnan(disparity)] = 0.0
    return disparity


__all__ = ["LR_SPAN", "apply_min_confidence", "check_min_confidence", "lr_confidence", "right_view"]
