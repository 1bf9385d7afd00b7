"""Census-SGM, the rSGM recipe used as the paper's classical matcher, in Cython.

Pipeline (each step is a public, validated function so it can be tested and
reused; the :class:`CensusSGM` matcher runs the same steps fused, in one C
driver per call, with the same results):

1. :func:`census_transform` -- 5 x 5 census on the gray image: 24 bits, bit set
   where the neighbour is darker than the centre, window scanned row-major
   (MSB first) skipping the centre, border pixels replicated.
2. :func:`hamming_cost_volume` -- ``C(y, x, d) = popcount(cL(y, x) ^ cR(y, x - d))``
   as uint16 H x W x D. Only ``d <= x`` has a right pixel to match (see
   "Left band" below); the volume holds :data:`INVALID_COST` (24) elsewhere,
   which no later step reads.
3. optional guided stereo (:func:`~vpp_service.matchers.guided.modulate_cost`)
   on the hinted pixels, before aggregation.
4. :func:`aggregate_costs` -- SGM over 8 paths (or 4: horizontal + vertical)
   with ``P1 = 11`` and the adaptive ``P2 = max(P2min, floor(gamma - alpha |I(p) - I(p - r)|), P1)``
   of Banz et al. (P2min = 17, alpha = 0.5, gamma = 35). Integer arithmetic:
   costs are clamped to :data:`COST_CAP` (4095) and P1, P2 <= 4095, so path
   costs fit int16 and the 8-path sum fits uint16 without overflow.
5. :func:`select_disparity` -- winner-takes-all (lowest ``d`` on ties) with a
   uniqueness test ``S_best < ratio * S_second`` (``S_second`` = min over
   ``|d - d_best| > 1``) and parabola sub-pixel refinement.
6. :func:`right_disparity` + :func:`left_right_check` -- the right view's WTA
   from the same aggregated volume, ``d_R(x) = argmin_d S(x + d, d)``; a left
   disparity survives if ``|d_L(x) - d_R(x - round(d_L(x)))| <= tolerance``.
7. :func:`~vpp_service.matchers.border.reject_border_matches` -- invalidate
   matches landing within ``border_margin`` columns of the right image's
   border (clamped census, truncated search; 0 turns it off).
8. :func:`~vpp_service.matchers.holes.fill_short_gaps` -- close row gaps of
   at most ``gap_size`` pixels (linear inside a surface, else background; 0
   turns it off), so the median and speckle filter see whole surfaces.
9. :func:`median_filter3x3` -- 3 x 3 median over the valid neighbours.
10. :func:`~vpp_service.matchers.speckle.remove_speckles` -- invalidate small
    blobs (rSGM's speckle filter; ``speckle_size`` 0 turns it off).

Left band: column ``x`` is matched over the disparities that exist there,
``0 <= d <= min(x, D - 1)``, so the leftmost ``D`` columns get a disparity
like every other pixel whose match can lie inside the right image (there is
no empty band of width ``D``). The aggregation treats the other entries as
absent (an infinite path cost: never a minimum, never a neighbour); their
aggregated cost is 65535; the WTA, its uniqueness test and the sub-pixel
parabola (which needs ``d_best + 1 <= x``) look only at the valid ones. For
``x < D - 1`` a minimum at ``d = x`` itself, the largest disparity that exists
there, is rejected (NaN): the cost was still falling where the right image
ends, so the match most likely lies outside it (on the 26 Middlebury scenes
keeping those minima costs 0.8 point of bad-2 after hole filling).

Everything invalid is NaN. Threads: every function takes ``threads``
(None = the project's default, :func:`vpp_service.threads.default_threads`);
the matcher's ``threads`` option defaults to 1 (see :class:`CensusSGMOptions`).
Results do not depend on the thread count nor on the build.

Kernels: the C in ``_census_sgm.h`` and the stage headers it includes is
compiled twice, portable and for x86-64-v3 (AVX2); the AVX2 build runs
exactly when :mod:`vpp_service.vpp.backend` runs the AVX2 build of the VPP
kernel (a CPU with AVX2, and ``VPP_NO_AVX2``
not set to 1). :meth:`CensusSGM.compute` runs one parallel region per call
(three with guided stereo: census and cost volume, the modulation, the rest):
the census of both images (rows in blocks), then the SGM: the forward pass
(left-to-right plus the three paths from the row above) and the backward
pass (the four mirrored paths) on two threads at once, each computing the
Hamming costs of a pixel as it goes (the cost volume is built only for guided
stereo) and storing the row's partial sum of its paths as uint8 when that
provably fits (Hamming costs <= 24 and ``paths / 2 * (24 + max P2) <= 255``,
true for the default penalties: a path cost is at most its matching cost plus
P2), else as uint16 (guided stereo, :meth:`CensusSGM.compute_from_cost`, large
penalties); under that bound the AVX2 build keeps the path costs as bytes too
(8 paths, ``max_disparity`` a multiple of 16). Each pass aggregates a row into
a scratch row of its own (in cache) and copies it out only when it reaches the
row first; the pass that comes second finishes the row (sum of the two passes,
left and right WTA, left-right check, border step, short gaps); then the
median on row blocks. So the aggregation uses at most two threads. The matcher
keeps its buffers (census codes, partial sums, the cost volume once guided
stereo needed it) between calls and reallocates them only when the image size,
``max_disparity`` or the thread count changes. The speckle filter runs last,
on row strips in parallel (:mod:`vpp_service.matchers.speckle`).

Speed: ``benchmarks/bench_matchers.py`` times the matcher and each of its
stages; the latest numbers are in ``benchmarks/results/bench_matchers.json``.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Mapping
from dataclasses import dataclass
from types import ModuleType
from typing import Annotated, TypedDict

import numpy as np

from vpp_service.matchers import _census_sgm as portable
from vpp_service.matchers.base import MATCHERS, Matcher, MatcherOptions, MatcherRuntime, check_max_disparity
from vpp_service.matchers.guided import modulate_cost
from vpp_service.matchers.holes import GAP_STEP
from vpp_service.matchers.inputs import check_array, check_disparity, check_hints, check_image, check_pair, to_gray
from vpp_service.matchers.speckle import remove_speckles
from vpp_service.settings import OneOf, Range
from vpp_service.threads import resolve_threads
from vpp_service.vpp import backend

#: Census bits (5 x 5 window minus the centre) = the largest Hamming cost.
CENSUS_BITS = 24
#: Cost the Hamming volume holds where ``x < d`` (no right pixel to match; never read by the SGM).
INVALID_COST = CENSUS_BITS
#: Aggregated cost of the entries ``x < d`` (absent disparities).
NO_COST = 65535
#: Costs are clamped to this before aggregation (keeps the arithmetic exact).
COST_CAP = 4095
#: Largest allowed P1 / P2.
PENALTY_CAP = 4095


def avx2_build() -> ModuleType | None:
    """The AVX2 build of the kernels when it exists and this CPU can run it, else None.

    The CPU check is :func:`vpp_service.vpp.backend.avx2_build`'s (the one place that tests the CPU).
    """
    if backend.avx2_build() is None:
        return None
    try:
        from vpp_service.matchers import _census_sgm_avx2
    except ImportError:  # not built (non-x86 platform or a compiler without -mavx2)
        return None
    return _census_sgm_avx2


#: The kernel build in use: AVX2 exactly when the VPP kernel's is (``VPP_NO_AVX2=1`` keeps the portable one).
_k: ModuleType = (avx2_build() or portable) if backend.AVX2 else portable


def _check_gray(img: object, name: str) -> np.ndarray:
    img = check_image(img, name)
    if img.ndim != 2:
        raise ValueError(f"{name} must be a 2-D (H x W) gray image, got shape {img.shape}")
    return img


def _check_volume(vol: object, name: str) -> np.ndarray:
    return check_array(vol, name, (np.uint16,), 3, "H x W x D")


def census_transform(gray: np.ndarray, threads: int | None = None) -> np.ndarray:
    """5 x 5 census transform.

    Parameters
    ----------
    gray : ndarray
        H x W uint8, C-contiguous.
    threads : int or None
        OpenMP threads (None = :func:`~vpp_service.threads.default_threads`).

    Returns
    -------
    ndarray
        H x W uint32 codes: for the 24 window offsets (dy, dx) in row-major
        order without (0, 0), ``code = code << 1 | (I(y+dy, x+dx) < I(y, x))``,
        coordinates clamped to the image.
    """
    _check_gray(gray, "gray")
    out = np.empty(gray.shape, np.uint32)
    _k.census5x5(gray, out, resolve_threads(threads))
    return out


def hamming_cost_volume(
    census_left: np.ndarray, census_right: np.ndarray, max_disparity: int, threads: int | None = None
) -> np.ndarray:
    """Hamming matching cost between census codes.

    Parameters
    ----------
    census_left, census_right : ndarray
        H x W uint32 codes (same shape, C-contiguous).
    max_disparity : int
        Number of disparities D (0 < D < W).

    Returns
    -------
    ndarray
        H x W x D uint16, ``popcount(cL[y, x] ^ cR[y, x - d])``; :data:`INVALID_COST` where ``x < d``.
    """
    check_array(census_left, "census_left", (np.uint32,), 2, "an H x W array")
    check_array(census_right, "census_right", (np.uint32,), 2, "an H x W array")
    if census_left.shape != census_right.shape:
        raise ValueError(
            f"census_left and census_right must have the same shape, got {census_left.shape} and {census_right.shape}"
        )
    check_max_disparity(max_disparity, census_left.shape[1])
    h, w = census_left.shape
    out = np.empty((h, w, int(max_disparity)), np.uint16)
    _k.hamming_volume(census_left, census_right, out, INVALID_COST, resolve_threads(threads))
    return out


def p2_table(p1: int = 11, p2_min: int = 17, alpha: float = 0.5, gamma: float = 35.0) -> np.ndarray:
    """Adaptive-P2 lookup: ``P2[g] = min(4095, max(p2_min, p1, floor(gamma - alpha * g)))`` for g = 0..255.

    ``g = |I(p) - I(p - r)|`` is the gray-level step along the path.
    """
    g = np.arange(256, dtype=np.float64)
    p2 = np.floor(gamma - alpha * g)
    p2 = np.maximum(p2, max(p2_min, p1))
    return np.minimum(p2, PENALTY_CAP).astype(np.int16)


def _check_penalties(p1: int, p2_min: int, alpha: float, gamma: float) -> None:
    for name, v in (("p1", p1), ("p2_min", p2_min)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not 0 <= v <= PENALTY_CAP:
            raise ValueError(f"{name} must be an integer in [0, {PENALTY_CAP}], got {v!r}")
    for name, x in (("alpha", alpha), ("gamma", gamma)):
        if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
            raise ValueError(f"{name} must be a finite number, got {x!r}")
    if alpha < 0:
        raise ValueError(f"alpha must be >= 0, got {alpha}")


def aggregate_costs(
    cost: np.ndarray,
    gray: np.ndarray,
    paths: int = 8,
    *,
    p1: int = 11,
    p2_min: int = 17,
    alpha: float = 0.5,
    gamma: float = 35.0,
    threads: int | None = None,
) -> np.ndarray:
    """Semi-global aggregation over 4 or 8 paths.

    ``L_r(p, d) = C(p, d) + min(L_r(p-r, d), L_r(p-r, d+-1) + P1, min_k L_r(p-r, k) + P2) - min_k L_r(p-r, k)``
    with ``L_r = C`` at the first pixel of a path and ``P2`` from :func:`p2_table`
    using the gray step between ``p`` and ``p - r``. Returns ``S = sum_r L_r``.
    Only ``d <= x`` exists at column ``x``: the minima and neighbours above
    run over the existing entries, and ``S`` holds :data:`NO_COST` elsewhere.

    Parameters
    ----------
    cost : ndarray
        H x W x D uint16 (values above :data:`COST_CAP` are clamped to it).
    gray : ndarray
        H x W uint8 left image (for the adaptive P2).
    paths : int
        8 (horizontal, vertical and diagonals; rSGM default) or 4 (horizontal, vertical).
    p1, p2_min, alpha, gamma
        Penalties, see :func:`p2_table`.
    threads : int or None
        OpenMP threads (None = :func:`~vpp_service.threads.default_threads`).

    Returns
    -------
    ndarray
        H x W x D uint16 aggregated cost (:data:`NO_COST` where ``x < d``).
    """
    _check_volume(cost, "cost")
    _check_gray(gray, "gray")
    if gray.shape != cost.shape[:2]:
        raise ValueError(f"gray must have shape {cost.shape[:2]}, got {gray.shape}")
    if paths not in (4, 8) or isinstance(paths, bool):
        raise ValueError(f"paths must be 4 or 8, got {paths!r}")
    _check_penalties(p1, p2_min, alpha, gamma)
    if cost.max() > COST_CAP:
        cost = np.minimum(cost, COST_CAP)
    out = np.empty_like(cost)
    _k.aggregate(cost, gray, out, int(paths), int(p1), p2_table(p1, p2_min, alpha, gamma), resolve_threads(threads))
    return out


def select_disparity(
    aggregated: np.ndarray, uniqueness: float = 0.95, subpixel: bool = True, threads: int | None = None
) -> np.ndarray:
    """Winner-takes-all with uniqueness test and parabola sub-pixel refinement.

    At column ``x`` only ``d <= min(x, D - 1)`` takes part, and for ``x < D - 1`` a minimum at ``d = x``
    gives NaN (the left band, see the module docstring).

    Parameters
    ----------
    aggregated : ndarray
        H x W x D uint16 aggregated cost.
    uniqueness : float
        In (0, 1]: keep ``d_best`` only if ``S_best < uniqueness * S_second``,
        ``S_second`` being the best cost with ``|d - d_best| > 1`` (no such
        ``d`` -> kept). 1.0 only rejects ties.
    subpixel : bool
        For ``0 < d < min(x, D - 1)`` with ``S(d-1) - 2 S(d) + S(d+1) > 0`` add
        ``(S(d-1) - S(d+1)) / (2 (S(d-1) - 2 S(d) + S(d+1)))``.

    Returns
    -------
    ndarray
        H x W float32 disparity, NaN where the uniqueness test fails.
    """
    _check_volume(aggregated, "aggregated")
    if isinstance(uniqueness, bool) or not isinstance(uniqueness, (int, float)) or not 0 < uniqueness <= 1:
        raise ValueError(f"uniqueness must be in (0, 1], got {uniqueness!r}")
    out = np.empty(aggregated.shape[:2], np.float32)
    _k.winner_takes_all(aggregated, out, float(uniqueness), bool(subpixel), resolve_threads(threads))
    return out


def right_disparity(aggregated: np.ndarray, threads: int | None = None) -> np.ndarray:
    """Integer disparity of the right view from the left-referenced volume.

    ``d_R(y, x) = argmin_d S(y, x + d, d)`` over ``x + d < W`` (lowest ``d`` on
    ties), as H x W float32 (always valid).
    """
    _check_volume(aggregated, "aggregated")
    out = np.empty(aggregated.shape[:2], np.float32)
    _k.right_disparity(aggregated, out, resolve_threads(threads))
    return out


def left_right_check(
    disp_left: np.ndarray, disp_right: np.ndarray, tolerance: float = 1.0, threads: int | None = None
) -> np.ndarray:
    """Invalidate left disparities that the right view does not confirm.

    Keeps ``d = disp_left(y, x)`` iff ``x_r = x - floor(d + 0.5)`` is inside the
    image, ``disp_right(y, x_r)`` is valid and ``|d - disp_right(y, x_r)| <= tolerance``.

    Returns
    -------
    ndarray
        New H x W float32 map, NaN where rejected or already invalid.
    """
    check_disparity(disp_left, "disp_left")
    check_disparity(disp_right, "disp_right")
    if disp_left.shape != disp_right.shape:
        raise ValueError(
            f"disp_left and disp_right must have the same shape, got {disp_left.shape} and {disp_right.shape}"
        )
    if (
        isinstance(tolerance, bool)
        or not isinstance(tolerance, (int, float))
        or not tolerance >= 0
        or math.isinf(tolerance)
    ):
        raise ValueError(f"tolerance must be a finite number >= 0, got {tolerance!r}")
    out = np.empty_like(disp_left)
    _k.left_right_check(disp_left, disp_right, out, float(tolerance), resolve_threads(threads))
    return out


def median_filter3x3(disparity: np.ndarray, threads: int | None = None) -> np.ndarray:
    """3 x 3 median of each valid pixel over its valid (non-NaN) neighbours.

    Even counts take the mean of the two middle values (as ``np.median``);
    NaN pixels stay NaN. Returns a new H x W float32 map.
    """
    check_disparity(disparity, "disparity")
    out = np.empty_like(disparity)
    _k.median3x3(disparity, out, resolve_threads(threads))
    return out


@dataclass(frozen=True)
class CensusSGMOptions(MatcherOptions):
    """Options of the ``census-sgm`` matcher (rSGM defaults).

    Attributes
    ----------
    paths : int
        SGM paths, 8 (default) or 4.
    p1, p2_min, p2_alpha, p2_gamma : int, int, float, float
        Penalties: P1 = 11, adaptive P2 = max(17, floor(35 - 0.5 |dI|)).
    uniqueness : float
        WTA uniqueness ratio in (0, 1], default 0.95.
    subpixel : bool
        Parabola refinement (default True).
    lr_check : bool
        Left-right consistency check (default True).
    lr_tolerance : float
        Allowed left-right difference in pixels (default 1).
    border_margin : int
        Matches whose right pixel lies within this many columns of the right
        image's border are rejected (default 2, the census radius; 0 = off),
        see :func:`~vpp_service.matchers.border.reject_border_matches`.
    gap_size : int
        Row gaps of at most this many invalid pixels between two valid ones are
        closed before the median (default 4; 0 = off), see
        :func:`~vpp_service.matchers.holes.fill_short_gaps`.
    median : bool
        3 x 3 median of the result (default True).
    speckle_size, speckle_diff : int, float
        Speckle filter (:func:`~vpp_service.matchers.speckle.remove_speckles`)
        after the median: regions of at most ``speckle_size`` pixels (default
        200; 0 = off) whose disparity steps stay within ``speckle_diff`` px
        (default 2) are invalidated, as in the paper's rSGM setup.
    guided_k, guided_c : float
        Guided-stereo modulation height and width (10 and 1) used with ``hints``.
    confidence_peak : float
        The confidence's peak-ratio margin, in (0, 1]: the peak term is
        ``min(1, (1 - S_best / S_second) / confidence_peak)`` (``S_second`` the best aggregated cost outside
        ``d_best +- 1``). Default 1: the plain peak ratio; a smaller margin calls flatter minima sure.
    threads : int
        OpenMP threads (default 1; 0 = :func:`~vpp_service.threads.default_threads`). Two threads run
        the forward and the backward SGM pass at once (they meet only through a
        per-row counter, no barrier per row); threads beyond two only share the
        census and the median. One thread is the default: on an oversubscribed
        machine (evaluation running several scenes in parallel, shared CI) a
        second thread gains little; set 2 (or 0) on a dedicated machine.
    """

    paths: Annotated[int, OneOf(4, 8)] = 8
    p1: Annotated[int, Range(0, PENALTY_CAP)] = 11
    p2_min: Annotated[int, Range(0, PENALTY_CAP)] = 17
    p2_alpha: Annotated[float, Range(0.0)] = 0.5
    p2_gamma: Annotated[float, Range()] = 35.0
    uniqueness: Annotated[float, Range(0.0, 1.0, lo_open=True)] = 0.95
    subpixel: bool = True
    lr_check: bool = True
    lr_tolerance: Annotated[float, Range(0.0)] = 1.0
    border_margin: Annotated[int, Range(0)] = 2
    gap_size: Annotated[int, Range(0)] = 4
    median: bool = True
    speckle_size: Annotated[int, Range(0)] = 200
    speckle_diff: Annotated[float, Range(0.0)] = 2.0
    guided_k: Annotated[float, Range(0.0, lo_open=True)] = 10.0
    guided_c: Annotated[float, Range(0.0, lo_open=True)] = 1.0
    confidence_peak: Annotated[float, Range(0.0, 1.0, lo_open=True)] = 1.0
    threads: Annotated[int, Range(0)] = 1


class StageParams(TypedDict):
    """The fields of ``_census_sgm.StageParams``: the settings of the SGM stage (:func:`stage_params`)."""

    paths: int
    p1: int
    uniqueness: float
    subpixel: bool
    lr_check: bool
    tolerance: float
    median: bool
    border_margin: int
    gap_size: int
    gap_step: float
    conf_peak: float
    wta: bool


def stage_params(options: CensusSGMOptions, *, wta: bool = True) -> StageParams:
    """The SGM stage's settings for ``options`` (the kernel's ``StageParams`` struct, one key per field).

    Parameters
    ----------
    options : CensusSGMOptions
        The (validated) matcher options.
    wta : bool
        False stops the stage after the aggregation (benchmarks time it so).

    Returns
    -------
    StageParams
        The dict the kernel's ``sgm_stage`` converts to its struct.
    """
    return StageParams(
        paths=int(options.paths),
        p1=int(options.p1),
        uniqueness=float(options.uniqueness),
        subpixel=bool(options.subpixel),
        lr_check=bool(options.lr_check),
        tolerance=float(options.lr_tolerance),
        median=bool(options.median),
        border_margin=int(options.border_margin),
        gap_size=int(options.gap_size),
        gap_step=GAP_STEP,
        conf_peak=float(options.confidence_peak),
        wta=wta,
    )


class SGMWorkspace:
    """The buffers of the census-SGM kernels for one (H, W, D, threads), kept between calls.

    ``cost_stage`` and ``sgm_stage`` of the kernel read them by name (the stubs in ``_census_sgm.pyi``
    type them); the sizes come from the kernel build in use.

    Parameters
    ----------
    h, w, d : int
        Image height and width, number of disparities.
    threads : int
        OpenMP threads of the kernels (>= 1).
    """

    def __init__(self, h: int, w: int, d: int, threads: int) -> None:
        self.key = (h, w, d, threads)
        self.padl = np.empty((h + 4, w + 4), np.uint8)
        self.padr = np.empty((h + 4, w + 4), np.uint8)
        self.cl = np.empty((h, w), np.uint32)
        self.cr = np.empty((h, w), np.uint32)
        self._cost: np.ndarray | None = None  # the Hamming volume, only for guided stereo
        self.work = np.empty(_k.cost_work_bytes(w, threads), np.uint8)
        self.vf = np.empty((h, w, d), np.uint16)
        self.vb = np.empty((h, w, d) if threads > 1 else (1, 1, 1), np.uint16)  # backward pass, 2nd thread
        self.rowcnt = np.empty(h, np.intc)
        self.scratch = np.empty(2 * _k.scratch_bytes(w, d) + 64, np.uint8)
        self.dl = np.empty((h, w), np.float32)
        self.dr = np.empty((h, w), np.float32)
        self.lr = np.empty((h, w), np.float32)
        self.mpad = np.empty((h + 2, w + 2), np.float32)

    @property
    def cost(self) -> np.ndarray:
        """The H x W x D uint16 cost volume (allocated at first use)."""
        if self._cost is None:
            self._cost = np.empty(self.key[:3], np.uint16)
        return self._cost


@MATCHERS.register("census-sgm")
class CensusSGM(Matcher):
    """Census 5 x 5 + Hamming + 8-path SGM (rSGM recipe), with guided stereo.

    Colour inputs are converted to gray (census needs one channel). The cost
    volume is exposed (:meth:`cost_volume`, :meth:`compute_from_cost`) so
    guided stereo or other cost manipulations can be inserted. The instance
    keeps its work buffers between calls (about ``3 H W D`` uint16 with two or
    more threads, ``2 H W D`` with one); a call made while another runs on
    the same instance (another thread) uses fresh buffers.
    """

    name = "census-sgm"
    Options = CensusSGMOptions
    options: CensusSGMOptions
    supports_guidance = True

    def __init__(self, options: CensusSGMOptions | Mapping[str, object] | None = None) -> None:
        super().__init__(options)
        o = self.options
        self._stage = stage_params(o)  # the options are frozen: the kernel's settings are built once
        self._p2lut = p2_table(o.p1, o.p2_min, o.p2_alpha, o.p2_gamma)
        self._p2lut.setflags(write=False)
        self._ws: SGMWorkspace | None = None
        self._ws_lock = threading.Lock()

    def _threads(self) -> int:
        return resolve_threads(self.options.threads or None)  # 0: the default policy

    def runtime(self) -> MatcherRuntime:
        """The Cython kernels on the CPU (``cython-avx2`` where the AVX2 build runs), int16 path costs."""
        engine = "cython" if _k is portable else "cython-avx2"
        return {"engine": engine, "device": "cpu", "precision": "int16", "threads": self._threads()}

    def cost_volume(self, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        """H x W x D uint16 Hamming cost of the 5 x 5 census of the gray pair (a new array)."""
        check_pair(left, right)
        check_max_disparity(self.options.max_disparity, left.shape[1])
        gl, gr = to_gray(left), to_gray(right)
        ws = SGMWorkspace(gl.shape[0], gl.shape[1], self.options.max_disparity, self._threads())
        self._census(gl, gr, ws, volume=True)
        return ws.cost

    def _census(self, gl: np.ndarray, gr: np.ndarray, ws: SGMWorkspace, *, volume: bool) -> None:
        """Census codes of the pair into ``ws`` and, with ``volume``, the Hamming volume ``ws.cost``."""
        _k.cost_stage(ws, gl, gr, ws.cost if volume else None, INVALID_COST, ws.key[3])

    def compute_from_cost(self, cost: np.ndarray, left_gray: np.ndarray, hints: np.ndarray | None = None) -> np.ndarray:
        """Disparity from a cost volume (steps 3-10; ``fill`` is not applied here).

        Parameters
        ----------
        cost : ndarray
            H x W x D uint16 cost volume, lower = better (e.g. :meth:`cost_volume`). Not modified.
        left_gray : ndarray
            The left image (H x W uint8, or H x W x C, converted to gray) for the adaptive P2.
        hints : ndarray or None
            Sparse disparity for guided stereo (NaN or <= 0 = none).

        Returns
        -------
        ndarray
            H x W float32, NaN = invalid.
        """
        _check_volume(cost, "cost")
        check_image(left_gray, "left_gray")
        gray = to_gray(left_gray)
        if gray.shape != cost.shape[:2]:
            raise ValueError(f"left_gray must be {cost.shape[:2]} (H x W), got {left_gray.shape}")
        h, w, d = cost.shape
        if hints is not None:
            hints = check_hints(hints, (h, w))
        return self._sgm(cost, gray, hints, SGMWorkspace(h, w, d, self._threads()), own_cost=False)

    def _sgm(
        self,
        cost: np.ndarray | None,
        gray: np.ndarray,
        hints: np.ndarray | None,
        ws: SGMWorkspace,
        *,
        own_cost: bool,
        right_gray: np.ndarray | None = None,
        conf: np.ndarray | None = None,
    ) -> np.ndarray:
        """Steps 3-8 on ``cost`` (modified in place only when ``own_cost``: the workspace's volume).

        ``cost`` None: the SGM passes compute the Hamming costs row by row from ``ws.cl``, ``ws.cr`` (no
        hints), which the same parallel region computes first from ``gray`` and ``right_gray`` when given.
        ``conf`` (H x W float32, or None): the kernel's confidence of each pixel goes there.
        """
        o = self.options
        t = ws.key[3]
        if cost is not None:
            if hints is not None:
                cost = modulate_cost(cost, hints, o.guided_k, o.guided_c, inplace=own_cost, threads=t)
                own_cost = True
            if cost.max(initial=0) > COST_CAP:
                cost = np.minimum(cost, COST_CAP, out=cost if own_cost else None)
        # The kernel finishes each row (left-right check, border step, short gaps) and runs the median in
        # its parallel region (with right_gray, the census first).
        out = np.empty(gray.shape, np.float32)
        _k.sgm_stage(self._stage, self._p2lut, ws, cost, gray, right_gray, out, t, conf)
        if o.speckle_size:
            out = remove_speckles(out, o.speckle_size, o.speckle_diff, threads=t)
        return out

    def _workspace(self, h: int, w: int) -> SGMWorkspace:
        key = (h, w, self.options.max_disparity, self._threads())
        if self._ws is None or self._ws.key != key:
            self._ws = None  # free the old buffers first
            self._ws = SGMWorkspace(*key)
        return self._ws

    def _compute(self, left: np.ndarray, right: np.ndarray, hints: np.ndarray | None) -> np.ndarray:
        return self._run(left, right, hints, None)

    def _compute_confidence(
        self, left: np.ndarray, right: np.ndarray, hints: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray]:
        """The disparity and the kernel's confidence, from the one SGM pass (no second matching).

        Per pixel, from its best disparity ``b`` (lowest aggregated cost ``S_best``): the peak ratio
        ``min(1, (1 - S_best / S_second) / confidence_peak)`` (``S_second`` the lowest cost with
        ``|d - b| > 1``) times the left-right term ``max(0, 1 - |b - d_R(x - b)| / (lr_tolerance + 1))``
        (``d_R`` the right view's WTA, computed even with ``lr_check`` off). The disparity is the same as
        :meth:`compute`'s.
        """
        conf = np.empty(left.shape[:2], np.float32)
        return self._run(left, right, hints, conf), conf

    def _run(
        self, left: np.ndarray, right: np.ndarray, hints: np.ndarray | None, conf: np.ndarray | None
    ) -> np.ndarray:
        gl, gr = to_gray(left), to_gray(right)
        h, w = gl.shape
        if not self._ws_lock.acquire(blocking=False):  # another thread is using the kept buffers
            ws = SGMWorkspace(h, w, self.options.max_disparity, self._threads())
            return self._match(gl, gr, hints, ws, conf)
        try:
            return self._match(gl, gr, hints, self._workspace(h, w), conf)
        finally:
            self._ws_lock.release()

    def _match(
        self, gl: np.ndarray, gr: np.ndarray, hints: np.ndarray | None, ws: SGMWorkspace, conf: np.ndarray | None
    ) -> np.ndarray:
        """Census and SGM in one parallel region; with hints, the census and cost volume first, then the SGM."""
        if hints is None:
            return self._sgm(None, gl, None, ws, own_cost=True, right_gray=gr, conf=conf)
        self._census(gl, gr, ws, volume=True)
        return self._sgm(ws.cost, gl, hints, ws, own_cost=True, conf=conf)


__all__ = [
    "CENSUS_BITS",
    "COST_CAP",
    "INVALID_COST",
    "NO_COST",
    "CensusSGM",
    "CensusSGMOptions",
    "aggregate_costs",
    "census_transform",
    "hamming_cost_volume",
    "left_right_check",
    "median_filter3x3",
    "p2_table",
    "right_disparity",
    "select_disparity",
]
