"""Virtual Pattern Projection: paint one pattern at both ends of each sparse match.

:func:`project` is the typed, validating wrapper of the Cython kernel
(:mod:`vpp_service.vpp._kernel`).  Semantics pinned down here (the reference
implementation ``tests/vpp_reference.py`` follows them literally):

Points
    ``disparity[y, x] = d``.  0 and NaN mean *no point*.  A *given* point is
    any other value; it is *invalid* (counted, skipped) if ``d < 0``, infinite
    or ``d >= W``.  A valid point matches ``x' = x - d`` (float64) on row ``y``
    of the right image; if ``x' < 0`` it is a *left-border* point
    (``out_of_bounds``): its left patch is still painted and the part of its
    right patch inside the image too.  float64 maps are converted to float32.

Order
    Points are painted in increasing ``d`` (far to near), ties by row then
    column; a later paint blends over an earlier one, so the foreground wins.
    All right-view paints are applied before the left-view ones (the FGD
    strategy therefore reads the *final* painted right image).

Patch
    Half-size ``h = (patch - 1) // 2``; patch pixel ``(dx, dy)``,
    ``|dx|, |dy| <= h``, sits at ``(x + dx, y + dy)`` in L and at column
    ``x' + dx`` of row ``y + dy`` in R.  A patch pixel whose *left* position is
    outside the image is skipped in both views.  Distance-adaptive patch: with
    ``u = clip((d - d_min) / (d_max - d_min), 0, 1)`` (``d_min`` = the frame's
    smallest valid d, ``d_max`` = ``adaptive_max_disparity`` or the largest),
    ``h(d) = floor(u ** gamma_d * h + 0.5)`` (h if ``d_max <= d_min``).
    Bilateral patch: pixel ``p`` of the patch centred on ``c`` is painted only
    if ``e < -ln(threshold)`` with ``e = |p - c|^2 / (2 sigma_s^2) +
    (sum_ch (L(p) - L(c))^2 / C) / (2 sigma_c^2)`` on the ORIGINAL left image
    (i.e. ``exp(-e) > threshold``).

Values
    random: channel ``c`` of :func:`vpp_service.vpp.rng.pattern_bytes` (seed,
    x, y) of the left pixel painted (per-pixel) or of the point (uniform): a
    seeded table of random bytes indexed by ``(x + 23679 y) mod 65536`` (see
    :mod:`vpp_service.vpp.rng`).
    histogram: per channel, occupancy of rows ``r - sh//2 .. r + sh//2`` and
    columns ``[c - L//2, c - L//2 + L - 1]`` (clipped) of the ORIGINAL left
    image around the left pixel and of the ORIGINAL right image around
    ``round(x') + dx`` (round half up; may be empty at the left border); the
    value is the ``i`` maximising the distance to the nearest filled bin
    (ties: smallest ``i``); if every bin is filled, the least frequent value
    (ties: smallest).  Uniform patches use the point's centre windows.

Blending (fixed point, weights quantised to 1/65536, round half up)
    ``w16(w) = floor(w * 65536 + 0.5)``; ``blend(I, A, w) = (I * (65536 - w)
    + A * w + 32768) >> 16``.  L pixel: ``blend(L, A, w16(alpha))``.
    R with splatting: ``fl = floor(x')``, ``beta = x' - fl``; column
    ``fl + dx`` gets ``blend(R, A, w16(alpha * (1 - beta)))`` then, if
    ``beta > 0``, column ``fl + dx + 1`` gets ``blend(R, A, w16(alpha * beta))``.
    Without splatting: column ``floor(x' + 0.5) + dx`` with ``w16(alpha)``.
    Columns outside the image are skipped.

Occlusion
    "off": no detection, all points visible.  "bkgd": detection runs (the mask
    is returned) but points are painted as visible.  "no": occluded points
    paint nothing.  "fgd": occluded points paint nothing in R; each of their
    left patch pixels becomes ``(L * (65536 - wa) * 65536 + V * wa + 2^31) >> 32``
    with ``wa = w16(alpha)`` and ``V = R(fl+dx) * (65536 - wb) + R(fl+dx+1) * wb``,
    ``wb = w16(beta)`` (``V = R(fl+dx) * 65536`` when ``beta == 0``; without
    splatting ``fl = floor(x' + 0.5)`` and ``beta = 0``) read from the final
    right image; pixels whose source columns leave the image are skipped.

Inputs are never modified; non-contiguous inputs are copied.  Results are
byte-identical for any ``num_threads``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import _kernel, backend
from .config import VPPConfig
from .occlusion import _NO_TABLE, check_occlusion_params, classify_into, penalty_table
from .rng import check_seed, kernel_table
from ._validate import as_disparity, as_image, as_threads

_OCC_MODE = {"off": 0, "no": 1, "bkgd": 2, "fgd": 3}


def _sweep_paints(config: VPPConfig) -> bool:
    """True when the fused sweep kernel paints this variant: the per-pixel random
    pattern without adaptive patches (the default (vi), and (ii))."""
    return (config.pattern == "random" and (not config.uniform_patch or config.patch == 1)
            and config.adaptive_patch is None)


@dataclass(frozen=True)
class VPPStats:
    """Point counts of one projection.

    Attributes
    ----------
    given : int
        Non-empty entries of the disparity map (not 0, not NaN).
    invalid : int
        Given points ignored (negative, infinite or >= image width).
    occluded : int
        Valid points classified occluded (0 when occlusion is "off").
    projected : int
        Valid points whose pattern was painted in both views (occluded points
        are excluded for "no" and "fgd").
    out_of_bounds : int
        Valid points whose match ``x - d`` falls left of column 0.
    """

    given: int
    projected: int
    occluded: int
    invalid: int
    out_of_bounds: int

    def to_dict(self) -> dict[str, int]:
        """Plain-dict form."""
        return {"given": self.given, "projected": self.projected, "occluded": self.occluded,
                "invalid": self.invalid, "out_of_bounds": self.out_of_bounds}


@dataclass(frozen=True)
class VPPResult:
    """Output of :func:`project`.

    Attributes
    ----------
    left, right : numpy.ndarray
        New painted uint8 images, same shape as the inputs.
    occluded : numpy.ndarray
        H x W bool, True at points classified occluded.
    stats : VPPStats
        Point counts.
    """

    left: np.ndarray
    right: np.ndarray
    occluded: np.ndarray
    stats: VPPStats


def project(left: np.ndarray, right: np.ndarray, disparity: np.ndarray,
            config: VPPConfig | None = None, *, seed: int = 0,
            num_threads: int | None = None) -> VPPResult:
    """Paint a virtual pattern on a rectified pair at the sparse correspondences.

    Parameters
    ----------
    left, right : numpy.ndarray
        Rectified uint8 images, H x W or H x W x C (C in {1, 3}), same shape.
    disparity : numpy.ndarray
        H x W float32 (or float64, converted) sparse disparity of the left
        view; 0 / NaN = no point.  See the module docstring for the rules.
    config : VPPConfig, optional
        The variant (default: pattern (vi), 3x3, alpha 0.4, FGD).
    seed : int
        Seed of the random pattern, in ``[0, 2**64)``.
    num_threads : int or None
        OpenMP threads (None: all cores); the output does not depend on it.

    Returns
    -------
    VPPResult
    """
    if config is None:
        config = VPPConfig()
    if not isinstance(config, VPPConfig):
        raise TypeError(f"config must be a VPPConfig, got {type(config).__name__}")
    seed = check_seed(seed)
    nt = as_threads(num_threads)
    L = as_image("left", left)
    R = as_image("right", right)
    if L.shape != R.shape:
        raise ValueError(f"left shape {left.shape} and right shape {right.shape} differ")
    H, W, C = L.shape
    disp = as_disparity("disparity", disparity, (H, W))
    rx, ry = check_occlusion_params((config.occ_window_x, config.occ_window_y),
                                    config.occ_lambda, config.occ_gamma, config.occ_t)
    out_l = np.empty_like(L)
    out_r = np.empty_like(R)
    occ = np.empty((H, W), dtype=bool)   # every row is written by the kernel
    occmode = _OCC_MODE[config.occlusion]
    pen = penalty_table((rx, ry), float(config.occ_lambda), float(config.occ_gamma))
    hmax = (config.patch - 1) // 2
    table = kernel_table(seed, C, hmax) if config.pattern == "random" else _NO_TABLE
    if _sweep_paints(config):
        stats, occ_rows = backend.sweep.sweep_kernel(
            disp, occ.view(np.uint8), occmode != 0, rx, ry, pen, float(config.occ_t),
            L, R, out_l, out_r, True, hmax, float(config.alpha), config.splat, occmode,
            table, nt)
    else:
        occ_rows = np.zeros(H, np.int64)
        if occmode != 0:
            _, occ_rows = classify_into(disp, occ, (rx, ry), pen, float(config.occ_t), nt)
        else:
            occ.fill(False)
        bil = config.adaptive_patch == "bilateral"
        stats = _kernel.project_kernel(
            L, R, disp, out_l, out_r, occ.view(np.uint8),
            0 if config.pattern == "random" else 1, config.uniform_patch, hmax,
            float(config.alpha), config.splat, occmode,
            config.adaptive_patch == "distance", float(config.adaptive_gamma),
            float(config.adaptive_max_disparity or 0.0),
            bil, 2.0 * config.bilateral_sigma_space ** 2, 2.0 * config.bilateral_sigma_color ** 2,
            -math.log(config.bilateral_threshold),
            config.search_width, config.search_height, table, nt)
    tot = stats.sum(axis=0)
    n_occ = int(occ_rows.sum())
    valid = int(tot[1])
    projected = valid - n_occ if occmode in (1, 3) else valid
    st = VPPStats(given=int(tot[0]), projected=projected, occluded=n_occ,
                  invalid=int(tot[2]), out_of_bounds=int(tot[3]))
    if left.ndim == 2:
        out_l = out_l[:, :, 0]
        out_r = out_r[:, :, 0]
    return VPPResult(left=out_l, right=out_r, occluded=occ, stats=st)
