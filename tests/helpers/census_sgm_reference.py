"""Plain numpy / Python Census-SGM, written for reading, not speed: the reference the kernels must equal.

Every step follows the definitions in :mod:`vpp_service.matchers.census_sgm` literally (one pixel, one
path, one disparity at a time where that is clearer). Column ``x`` has the disparities ``d <= min(x, D - 1)``;
the others are absent: an infinite path cost in the aggregation, :data:`NO_COST` in the aggregated volume.
"""

from __future__ import annotations

import math
from types import ModuleType

import numpy as np

from vpp_service.matchers import census_sgm as cs

#: The builds of the Census-SGM kernels this machine can run (None: no AVX2 build / CPU).
CENSUS_BUILDS: dict[str, ModuleType | None] = {"portable": cs.portable, "avx2": cs.avx2_build()}

OFFSETS = [(dy, dx) for dy in range(-2, 3) for dx in range(-2, 3) if (dy, dx) != (0, 0)]


def ref_census(img: np.ndarray) -> np.ndarray:
    """24-bit 5x5 census: for each offset in row-major order, ``code = code << 1 | (neighbour < centre)``."""
    h, w = img.shape
    pad = np.pad(img, 2, mode="edge").astype(np.int32)
    code = np.zeros((h, w), np.uint32)
    for dy, dx in OFFSETS:
        nb = pad[2 + dy : 2 + dy + h, 2 + dx : 2 + dx + w]
        code = (code << np.uint32(1)) | (nb < img).astype(np.uint32)
    return code


def ref_hamming(cl: np.ndarray, cr: np.ndarray, D: int) -> np.ndarray:
    """``popcount(cl[y, x] ^ cr[y, x - d])`` for ``d <= x``, :data:`INVALID_COST` elsewhere."""
    h, w = cl.shape
    out = np.full((h, w, D), cs.INVALID_COST, np.uint16)
    for d in range(D):
        x = np.bitwise_xor(cl[:, d:], cr[:, : w - d])
        out[:, d:, d] = np.array([int(v).bit_count() for v in x.ravel()]).reshape(x.shape)
    return out


def ref_aggregate(
    C: np.ndarray, g: np.ndarray, paths: int, *, p1: int, p2min: int, alpha: float, gamma: float
) -> np.ndarray:
    """Sum over the paths of ``L_r`` (int64), :data:`NO_COST` where ``x < d``.

    ``L_r(p, d) = C(p, d) + min(L_r(p-r, d), L_r(p-r, d+-1) + P1, min_k L_r(p-r, k) + P2) - min_k L_r(p-r, k)``
    over the existing ``d`` of ``p``, ``L_r = C`` at a path's first pixel, absent entries infinite.
    """
    H, W, D = C.shape
    C = np.minimum(C.astype(np.int64), cs.COST_CAP)
    dirs = [(0, 1), (0, -1), (1, 0), (-1, 0)]
    if paths == 8:
        dirs += [(1, 1), (1, -1), (-1, 1), (-1, -1)]
    S = np.zeros((H, W, D), np.float64)
    for dy, dx in dirs:
        L = np.full((H, W, D), np.inf)
        for y in range(H) if dy >= 0 else range(H - 1, -1, -1):
            for x in range(W) if dx >= 0 else range(W - 1, -1, -1):
                n = min(x + 1, D)  # d = 0 .. n - 1 exist at column x
                py, px = y - dy, x - dx
                if not (0 <= py < H and 0 <= px < W):
                    L[y, x, :n] = C[y, x, :n]
                    continue
                prev = L[py, px]
                m = prev.min()
                step = abs(int(g[y, x]) - int(g[py, px]))
                p2 = max(p2min, p1, math.floor(gamma - alpha * step))
                for d in range(n):
                    v = min(prev[d], m + p2)
                    if d > 0:
                        v = min(v, prev[d - 1] + p1)
                    if d < D - 1:
                        v = min(v, prev[d + 1] + p1)
                    L[y, x, d] = C[y, x, d] + v - m
        S += L
    S[np.isinf(S)] = cs.NO_COST
    return S.astype(np.int64)


def ref_wta(S: np.ndarray, uniqueness: float, subpixel: bool) -> np.ndarray:
    """Left WTA over ``d <= min(x, D - 1)``: first minimum, uniqueness vs ``|d - best| > 1``, parabola.

    For ``x < D - 1`` a minimum at ``d = x`` is rejected (NaN).
    """
    H, W, D = S.shape
    out = np.full((H, W), np.nan, np.float32)
    for y in range(H):
        for x in range(W):
            c = [int(v) for v in S[y, x, : min(x + 1, D)]]
            best = int(np.argmin(c))
            if len(c) < D and best == len(c) - 1:  # left band: the minimum at d = x may lie beyond the image
                continue
            others = [c[d] for d in range(len(c)) if abs(d - best) > 1]
            if others and not c[best] < uniqueness * min(others):
                continue
            val = float(best)
            if subpixel and 0 < best < len(c) - 1:
                den = c[best - 1] - 2 * c[best] + c[best + 1]
                if den > 0:
                    val = best + (c[best - 1] - c[best + 1]) / (2.0 * den)
            out[y, x] = val
    return out


def ref_right(S: np.ndarray) -> np.ndarray:
    """``argmin_d S[y, xr + d, d]`` over ``xr + d < W`` (first minimum)."""
    H, W, D = S.shape
    out = np.zeros((H, W), np.float32)
    for y in range(H):
        for xr in range(W):
            c = [S[y, xr + d, d] for d in range(D) if xr + d < W]
            out[y, xr] = int(np.argmin(c))
    return out


def ref_lr(dl: np.ndarray, dr: np.ndarray, tol: float) -> np.ndarray:
    """Keep ``d = dl(x)`` iff ``dr(x - floor(d + 0.5))`` exists, is valid and within ``tol``."""
    out = np.full_like(dl, np.nan)
    H, W = dl.shape
    for y in range(H):
        for x in range(W):
            d = dl[y, x]
            if np.isnan(d):
                continue
            xr = x - math.floor(float(d) + 0.5)
            if 0 <= xr < W and not np.isnan(dr[y, xr]) and abs(float(d) - float(dr[y, xr])) <= tol:
                out[y, x] = d
    return out


def ref_median(a: np.ndarray) -> np.ndarray:
    """3x3 ``np.median`` of the valid neighbours of each valid pixel."""
    H, W = a.shape
    out = np.full_like(a, np.nan)
    for y in range(H):
        for x in range(W):
            if np.isnan(a[y, x]):
                continue
            win = a[max(0, y - 1) : y + 2, max(0, x - 1) : x + 2]
            out[y, x] = np.median(win[~np.isnan(win)])
    return out


def ref_reject(a: np.ndarray, margin: int) -> np.ndarray:
    """Plain reject_border_matches: NaN where x - floor(d + 0.5) is not within margin of the right image."""
    out = a.astype(np.float32).copy()
    h, w = a.shape
    for y in range(h):
        for x in range(w):
            d = float(a[y, x])
            if math.isnan(d):
                continue
            xr = x - math.floor(d + 0.5)
            if not margin <= xr <= w - 1 - margin:
                out[y, x] = np.nan
    return out


def ref_short_gaps(a: np.ndarray, max_gap: int, max_step: float) -> np.ndarray:
    """Plain-python fill_short_gaps: interior NaN runs <= max_gap, linear if the ends are close, else the smaller."""
    out = a.astype(np.float32).copy()
    h, w = a.shape
    for y in range(h):
        x = 0
        while x < w:
            if not np.isnan(a[y, x]):
                x += 1
                continue
            end = x
            while end < w and np.isnan(a[y, end]):
                end += 1
            n = end - x
            if x > 0 and end < w and n <= max_gap:
                lo, hi = float(a[y, x - 1]), float(a[y, end])
                for j in range(n):
                    if abs(lo - hi) <= max_step:
                        out[y, x + j] = np.float32(lo + (hi - lo) * (j + 1) / (n + 1))
                    else:
                        out[y, x + j] = min(lo, hi)
            x = end
    return out


def ref_match(
    gl: np.ndarray,
    gr: np.ndarray,
    D: int,
    *,
    paths: int = 8,
    uniqueness: float = 0.95,
    subpixel: bool = True,
    lr_check: bool = True,
    median: bool = True,
    border_margin: int = 2,
    gap_size: int = 4,
    cost: np.ndarray | None = None,
    p1: int = 11,
    p2_min: int = 17,
    p2_alpha: float = 0.5,
    p2_gamma: float = 35.0,
) -> np.ndarray:
    """The matcher's chain without the speckle filter (rSGM penalties by default).

    ``cost`` replaces the Hamming volume; ``p1`` .. ``p2_gamma`` as in the matcher's options.
    """
    if cost is None:
        cost = ref_hamming(ref_census(gl), ref_census(gr), D)
    S = ref_aggregate(cost, gl, paths, p1=p1, p2min=p2_min, alpha=p2_alpha, gamma=p2_gamma)
    disp = ref_wta(S, uniqueness, subpixel)
    if lr_check:
        disp = ref_lr(disp, ref_right(S), 1.0)
    if border_margin:
        disp = ref_reject(disp, border_margin)
    if gap_size:
        disp = ref_short_gaps(disp, gap_size, 2.0)
    if median:
        disp = ref_median(disp)
    return disp


def ref_confidence(S: np.ndarray, peak: float, tol: float = 1.0) -> np.ndarray:
    """The kernel's confidence: peak-ratio term of the best ``b`` times the left-right term of ``b``.

    Over ``d <= min(x, D - 1)``: ``b`` the first minimum (before the uniqueness test and the left band's
    rejection), ``second`` the minimum over ``|d - b| > 1``;
    ``pk = min(1, (1 - S[b] / second) / peak)`` (0 without ``second`` or when it is 0), stored as float32;
    ``lr = 1 - |b - ref_right(S)[x - b]| / (tol + 1)``; confidence ``pk * lr`` where ``lr > 0``, else 0.
    """
    H, W, D = S.shape
    dr = ref_right(S)
    out = np.zeros((H, W), np.float32)
    for y in range(H):
        for x in range(W):
            c = [int(v) for v in S[y, x, : min(x + 1, D)]]
            best = int(np.argmin(c))
            others = [c[d] for d in range(len(c)) if abs(d - best) > 1]
            second = min(others) if others else 0
            pk = np.float32(min(1.0, (1.0 - c[best] / second) / peak)) if second > 0 else np.float32(0.0)
            lr = 1.0 - abs(best - float(dr[y, x - best])) / (tol + 1.0)
            out[y, x] = np.float32(float(pk) * lr) if lr > 0 else 0.0
    return out
