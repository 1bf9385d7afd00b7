"""Occlusion detection of sparse disparity points (VPP spec step 2).

Each valid point is warped to the right view at ``x - round(d)``; a point is
occluded if it loses its warped cell to a larger ``d`` or if a neighbour
within the ``r_x x r_y`` window is nearer by more than ``t`` plus a distance
penalty.  The exact rule is ``ref_occlusions`` in ``tests/vpp_reference.py``
(its executable form); the kernel is :mod:`vpp_service.vpp._sweep`.
"""

from __future__ import annotations

import numpy as np

from vpp_service.threads import resolve_threads
from vpp_service.vpp import backend
from vpp_service.vpp._validate import as_disparity
from vpp_service.vpp.config import VPPConfig
from vpp_service.vpp.params import kernel_params


def detect_occlusions(
    disparity: np.ndarray,
    *,
    window: tuple[int | np.integer, int | np.integer] = (9, 7),
    lam: float | np.floating = 2.0,
    gamma: float | np.floating = 0.4375,
    t: float | np.floating = 1.0,
    threads: int | None = None,
) -> np.ndarray:
    """Classify the sparse points of a disparity map as occluded in the right view.

    Parameters
    ----------
    disparity : numpy.ndarray
        H x W float32 (float64 is converted) sparse disparity of the left view;
        0 or NaN = no point; negative, infinite or >= W values are ignored.
    window : tuple of int
        ``(r_x, r_y)``, odd window sizes of the neighbourhood (Python or
        numpy integers).  Default (9, 7).
    lam, gamma, t : float
        Heuristic parameters (Python or numpy floats; defaults 2, 0.4375,
        1).  They are validated as the ``occ_window_x``, ``occ_window_y``,
        ``occ_lambda``, ``occ_gamma`` and ``occ_t`` fields of
        :class:`VPPConfig`.
    threads : int or None
        OpenMP threads (None: all cores).  The result does not depend on it.

    Returns
    -------
    numpy.ndarray
        H x W bool, True at the points classified occluded.
    """
    if not isinstance(window, (tuple, list)) or len(window) != 2:
        raise TypeError(f"window must be a pair of ints (rx, ry), got {window!r}")
    rx, ry = (v.item() if isinstance(v, np.integer) else v for v in window)
    lam, gamma, t = (v.item() if isinstance(v, np.generic) else v for v in (lam, gamma, t))
    config = VPPConfig(occ_window_x=rx, occ_window_y=ry, occ_lambda=lam, occ_gamma=gamma, occ_t=t)
    disp = as_disparity("disparity", disparity)
    nt = resolve_threads(threads, "threads")
    occ = np.empty(disp.shape, dtype=bool)  # every row is written by the kernel
    backend.sweep.occlusions(disp, occ.view(np.uint8), kernel_params(config), nt)
    return occ
