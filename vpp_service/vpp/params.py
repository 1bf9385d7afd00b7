"""The kernel's parameters: the one translation of a :class:`VPPConfig` for the compiled sweep.

:func:`kernel_params` fills the ``Params`` struct of ``_sweep.pyx`` (one key
per field; Cython converts the dict) with the named modes of ``_sweep.h``
(:class:`~vpp_service.vpp._sweep.Pattern`, ``Occlusion``, ``PatchMask``).
"""

from __future__ import annotations

import math
from typing import TypedDict

import numpy as np

from vpp_service.vpp import _sweep
from vpp_service.vpp.config import VPPConfig

_PATTERN = {"random": _sweep.Pattern.RANDOM, "histogram": _sweep.Pattern.HISTOGRAM}
_OCCLUSION = {
    "off": _sweep.Occlusion.OCC_OFF,
    "no": _sweep.Occlusion.OCC_NO,
    "bkgd": _sweep.Occlusion.OCC_BKGD,
    "fgd": _sweep.Occlusion.OCC_FGD,
}
_MASK = {
    None: _sweep.PatchMask.MASK_FULL,
    "distance": _sweep.PatchMask.MASK_DISTANCE,
    "bilateral": _sweep.PatchMask.MASK_BILATERAL,
}


class KernelParams(TypedDict):
    """The fields of ``_sweep.Params``."""

    pattern: int
    uniform: bool
    hmax: int
    alpha: float
    splat: bool
    occlusion: int
    occ_window_x: int
    occ_window_y: int
    occ_lambda: float
    occ_gamma: float
    occ_t: float
    mask: int
    adaptive_gamma: float
    adaptive_dmin: float
    adaptive_dmax: float
    two_ss: float
    two_sc: float
    neglogthr: float
    search_width: int
    search_height: int


def adaptive_range(config: VPPConfig, disparity: np.ndarray) -> tuple[float, float]:
    """The disparity range ``(d_min, d_max)`` of the distance-adaptive patch.

    ``d_min`` is the smallest valid d of the frame; ``d_max`` is
    ``config.adaptive_max_disparity`` when set, else the largest valid d.
    Both are 0 when the frame has no valid point (0 < d < W).

    Parameters
    ----------
    config : VPPConfig
        The variant (only ``adaptive_max_disparity`` is read).
    disparity : numpy.ndarray
        H x W float32 disparity map of the frame.

    Returns
    -------
    tuple of float
        ``(d_min, d_max)``.
    """
    with np.errstate(invalid="ignore"):
        valid = disparity[(disparity > 0) & (disparity < disparity.shape[1])]
    dmin, dmax = (float(valid.min()), float(valid.max())) if valid.size else (0.0, 0.0)
    if config.adaptive_max_disparity is not None:
        dmax = float(config.adaptive_max_disparity)
    return dmin, dmax


def kernel_params(config: VPPConfig, disparity: np.ndarray | None = None) -> KernelParams:
    """The kernel's parameters for ``config``.

    Parameters
    ----------
    config : VPPConfig
        The (already validated) variant.
    disparity : numpy.ndarray, optional
        The frame's float32 disparity map; needed only by the distance-adaptive
        patch (its range of d).
    """
    dmin, dmax = (
        adaptive_range(config, disparity)
        if config.adaptive_patch == "distance" and disparity is not None
        else (0.0, 0.0)
    )
    return KernelParams(
        pattern=int(_PATTERN[config.pattern]),
        uniform=config.uniform_patch and config.patch > 1,
        hmax=(config.patch - 1) // 2,
        alpha=float(config.alpha),
        splat=config.splat,
        occlusion=int(_OCCLUSION[config.occlusion]),
        occ_window_x=config.occ_window_x,
        occ_window_y=config.occ_window_y,
        occ_lambda=float(config.occ_lambda),
        occ_gamma=float(config.occ_gamma),
        occ_t=float(config.occ_t),
        mask=int(_MASK[config.adaptive_patch]),
        adaptive_gamma=float(config.adaptive_gamma),
        adaptive_dmin=dmin,
        adaptive_dmax=dmax,
        two_ss=2.0 * config.bilateral_sigma_space**2,
        two_sc=2.0 * config.bilateral_sigma_color**2,
        neglogthr=-math.log(config.bilateral_threshold),
        search_width=config.search_width,
        search_height=config.search_height,
    )
