"""Non-occlusion masks derived from left and right ground-truth disparity maps.

Middlebury 2001-2006 ship the ground truth of both views (``disp1``/``disp5``,
``disp2``/``disp6``) but no occlusion mask. A left pixel is *non-occluded* when
its match in the right view carries (nearly) the same disparity: the standard
left-right consistency check, which is how the benchmark's own masks were made.
"""

from __future__ import annotations

import numpy as np


def lr_consistency_mask(disp_left: np.ndarray, disp_right: np.ndarray, tol: float = 1.0) -> np.ndarray:
    """True at left pixels whose right-view match has a consistent disparity.

    Parameters
    ----------
    disp_left, disp_right : ndarray
        H x W float disparity of the left and of the right view (NaN = invalid);
        the match of left ``(x, y)`` is right ``(round(x - d), y)``.
    tol : float
        Largest accepted ``|d_left - d_right|`` in pixels (>= 0).

    Returns
    -------
    ndarray
        H x W bool mask; False where the left disparity is invalid, the match
        falls outside the right image, or the check fails.
    """
    for arg, a in (("disp_left", disp_left), ("disp_right", disp_right)):
        if not isinstance(a, np.ndarray) or a.ndim != 2 or not np.issubdtype(a.dtype, np.floating):
            raise ValueError(f"{arg}: must be a 2-D float array")
    if disp_left.shape != disp_right.shape:
        raise ValueError(f"disp_right: shape {disp_right.shape} differs from disp_left {disp_left.shape}")
    if not np.isfinite(tol) or tol < 0:
        raise ValueError(f"tol: must be a finite number >= 0, got {tol!r}")
    h, w = disp_left.shape
    xs = np.arange(w, dtype=np.float64)[None, :]
    valid = np.isfinite(disp_left)
    xr = np.rint(xs - np.where(valid, disp_left, 0.0)).astype(np.int64)
    inside = valid & (xr >= 0) & (xr < w)
    rows = np.broadcast_to(np.arange(h)[:, None], (h, w))
    dr = disp_right[rows, np.clip(xr, 0, w - 1)]
    with np.errstate(invalid="ignore"):
        ok = np.abs(dr - disp_left) <= tol
    return inside & np.isfinite(dr) & ok


__all__ = ["lr_consistency_mask"]
