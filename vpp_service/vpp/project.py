"""Virtual Pattern Projection: paint one pattern at both ends of each sparse match.

:func:`project` is the typed, validating wrapper of the sweep kernel
(:mod:`vpp_service.vpp._sweep`, one build chosen by :mod:`~vpp_service.vpp.backend`).
In short: every valid point ``(x, y, d)`` (0 < d < W) paints a patch of
pattern values around ``(x, y)`` in the left view and around ``x' = x - d``
(splatted over two columns) in the right view, far points first, blending
with weight ``alpha``; occluded points paint nothing ("no") or copy the right
view's content into the left patch ("fgd").  The rules, to the rounding, are
written once, as code: ``tests/vpp_reference.py`` (the literal reference the
kernel matches byte for byte); ``docs/algorithm.md`` explains them.

Inputs are never modified; non-contiguous inputs are copied.  Results are
byte-identical for any ``threads``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vpp_service.threads import resolve_threads
from vpp_service.vpp import backend
from vpp_service.vpp._validate import as_disparity, as_image
from vpp_service.vpp.config import VPPConfig
from vpp_service.vpp.params import kernel_params
from vpp_service.vpp.rng import check_seed, kernel_table


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
        return {
            "given": self.given,
            "projected": self.projected,
            "occluded": self.occluded,
            "invalid": self.invalid,
            "out_of_bounds": self.out_of_bounds,
        }


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


def project(
    left: np.ndarray,
    right: np.ndarray,
    disparity: np.ndarray,
    config: VPPConfig | None = None,
    *,
    seed: int = 0,
    threads: int | None = None,
) -> VPPResult:
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
    threads : int or None
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
    nt = resolve_threads(threads, "threads")
    L = as_image("left", left)
    R = as_image("right", right)
    if L.shape != R.shape:
        raise ValueError(f"left shape {left.shape} and right shape {right.shape} differ")
    H, W, C = L.shape
    disp = as_disparity("disparity", disparity, (H, W))
    out_l = np.empty_like(L)
    out_r = np.empty_like(R)
    occ = np.empty((H, W), dtype=bool)  # every row is written by the kernel
    table = kernel_table(seed, C, (config.patch - 1) // 2) if config.pattern == "random" else None
    stats, occ_rows = backend.sweep.paint(
        disp, occ.view(np.uint8), L, R, out_l, out_r, kernel_params(config, disp), table, nt
    )
    tot = stats.sum(axis=0)
    n_occ = int(occ_rows.sum())
    valid = int(tot[1])
    projected = valid - n_occ if config.occlusion in ("no", "fgd") else valid
    st = VPPStats(
        given=int(tot[0]), projected=projected, occluded=n_occ, invalid=int(tot[2]), out_of_bounds=int(tot[3])
    )
    if left.ndim == 2:
        out_l = out_l[:, :, 0]
        out_r = out_r[:, :, 0]
    return VPPResult(left=out_l, right=out_r, occluded=occ, stats=st)
