"""Occlusion detection of sparse disparity points (VPP spec step 2).

Every valid point ``(x, y, d)`` is warped to the right view at column
``x_w = x - round(d)`` (round half up) on row ``y``.  Where several points land
on one cell the largest ``d`` is kept and the others are *occluded*.  A kept
point ``(x_o, y_o)`` is occluded if at least one other kept point ``(x, y)``
with ``|x - x_o| <= r_x // 2`` and ``|y - y_o| <= r_y // 2`` satisfies::

    (W(x, y) - W(x_o, y_o)) - lam * (gamma * |x - x_o| + (1 - gamma) * |y - y_o|) > t

evaluated in float64 from the float32 disparities (penalty table precomputed
with exactly that expression).  The grid is conceptually unbounded on the
left, so points whose match falls left of column 0 are tested among
themselves.  The result is warped back: the mask is set at each occluded
point's own left-view pixel.  The kernel keeps only ``r_y`` dense warped rows
per thread: see :mod:`vpp_service.vpp._sweep` (and :mod:`vpp_service.vpp.backend`).
"""
from __future__ import annotations

import math

import numpy as np

from . import backend
from ._validate import as_disparity, as_threads

_NO_IMAGE = np.zeros((1, 1, 1), np.uint8)   # image arguments of a classify-only sweep
_NO_TABLE = np.zeros(1, np.uint8)           # pattern-table argument of a sweep that paints no random pattern


def penalty_table(window: tuple[int, int], lam: float, gamma: float) -> np.ndarray:
    """Distance penalty ``lam * (gamma * |dx| + (1 - gamma) * |dy|)`` indexed ``[|dy|, |dx|]``."""
    rx, ry = window
    adx = np.arange(rx // 2 + 1, dtype=np.float64)[None, :]
    ady = np.arange(ry // 2 + 1, dtype=np.float64)[:, None]
    return np.ascontiguousarray(lam * (gamma * adx + (1.0 - gamma) * ady))


def check_occlusion_params(window: object, lam: object, gamma: object, t: object) -> tuple[int, int]:
    """Validate the heuristic's parameters; returns ``(rx, ry)``."""
    if (not isinstance(window, (tuple, list)) or len(window) != 2
            or not all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) for v in window)):
        raise TypeError(f"window must be a pair of ints (rx, ry), got {window!r}")
    rx, ry = int(window[0]), int(window[1])
    if rx < 1 or ry < 1 or rx % 2 == 0 or ry % 2 == 0:
        raise ValueError(f"window sizes must be odd and >= 1, got {window!r}")
    for name, v in (("lam", lam), ("gamma", gamma), ("t", t)):
        if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) \
                or not math.isfinite(v):
            raise ValueError(f"{name} must be a finite number, got {v!r}")
    if lam < 0:
        raise ValueError(f"lam must be >= 0, got {lam}")
    if not 0.0 <= gamma <= 1.0:
        raise ValueError(f"gamma must be in [0, 1], got {gamma}")
    if t < 0:
        raise ValueError(f"t must be >= 0, got {t}")
    return rx, ry


def classify_into(disp: np.ndarray, occ: np.ndarray, window: tuple[int, int],
                  pen: np.ndarray, t: float, num_threads: int) -> tuple[np.ndarray, np.ndarray]:
    """Kernel call behind :func:`detect_occlusions` (inputs already validated).

    Fills ``occ`` (H x W bool, any initial content): True at the occluded points, and
    returns ``(row stats H x 4, occluded count per row)``.
    """
    return backend.sweep.sweep_kernel(disp, occ.view(np.uint8), True, window[0], window[1], pen, t,
                               _NO_IMAGE, _NO_IMAGE, _NO_IMAGE, _NO_IMAGE, False, 0, 0.0, False,
                               3, _NO_TABLE, num_threads)


def detect_occlusions(disparity: np.ndarray, *, window: tuple[int, int] = (9, 7),
                      lam: float = 2.0, gamma: float = 0.4375, t: float = 1.0,
                      num_threads: int | None = None) -> np.ndarray:
    """Classify the sparse points of a disparity map as occluded in the right view.

    Parameters
    ----------
    disparity : numpy.ndarray
        H x W float32 (float64 is converted) sparse disparity of the left view;
        0 or NaN = no point; negative, infinite or >= W values are ignored.
    window : tuple of int
        ``(r_x, r_y)``, odd window sizes of the neighbourhood.  Default (9, 7).
    lam, gamma, t : float
        Heuristic parameters (defaults 2, 0.4375, 1).
    num_threads : int or None
        OpenMP threads (None: all cores).  The result does not depend on it.

    Returns
    -------
    numpy.ndarray
        H x W bool, True at the points classified occluded.
    """
    rx, ry = check_occlusion_params(window, lam, gamma, t)
    disp = as_disparity("disparity", disparity)
    nt = as_threads(num_threads)
    occ = np.empty(disp.shape, dtype=bool)   # every row is written by the kernel
    classify_into(disp, occ, (rx, ry), penalty_table((rx, ry), float(lam), float(gamma)),
                  float(t), nt)
    return occ
