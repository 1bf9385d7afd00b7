"""The rules of VPP in executable form: a slow, literal NumPy/Python reference.

This module IS the definition of what ``vpp_service.vpp.project`` and
``vpp_service.vpp.detect_occlusions`` compute, to the last rounding; the
compiled kernel must match it byte for byte on both builds and every thread
count (``tests/test_vpp_*.py``).  ``docs/algorithm.md`` ("The rules")
summarises the rules in prose; where the two differ, this module is right.

It shares only the random-pattern table (``vpp_service.vpp.rng``) with the
library.  Everything else is a direct transcription of the rules, one step
after another, with no attempt at speed: a dense warped grid for the
occlusions, a global sort of the points, a loop over the patch pixels and
explicit histograms.
"""

from __future__ import annotations

import math

import numpy as np

from vpp_service.vpp.config import VPPConfig
from vpp_service.vpp.rng import pattern_bytes

#: A valid point: (d, y, x); sorting these gives the paint order.
Point = tuple[float, int, int]


def w16(w: float) -> int:
    return math.floor(w * 65536.0 + 0.5)


def blend(i: int, a: int, w: int) -> int:
    return (int(i) * (65536 - w) + int(a) * w + 32768) >> 16


def valid_points(disp: np.ndarray) -> list[Point]:
    H, W = disp.shape
    pts: list[Point] = []
    for y in range(H):
        for x in range(W):
            v = float(disp[y, x])
            if v > 0 and v < W:
                pts.append((v, y, x))
    return pts


def ref_occlusions(
    disp: np.ndarray, window: tuple[int, int] = (9, 7), lam: float = 2.0, gamma: float = 0.4375, t: float = 1.0
) -> np.ndarray:
    """Dense-grid literal occlusion heuristic."""
    disp = disp.astype(np.float32)
    H, W = disp.shape
    rx2, ry2 = window[0] // 2, window[1] // 2
    occ = np.zeros((H, W), bool)
    grid: dict[tuple[int, int], tuple[float, int]] = {}  # (xw, y) -> (d, x) winner
    for d, y, x in valid_points(disp):
        xw = x - math.floor(d + 0.5)
        cur = grid.get((xw, y))
        if cur is None or d > cur[0]:
            if cur is not None:
                occ[y, cur[1]] = True
            grid[(xw, y)] = (d, x)
        else:
            occ[y, x] = True
    for (xo, yo), (do, x0) in grid.items():
        hit = False
        for yy in range(yo - ry2, yo + ry2 + 1):
            for xx in range(xo - rx2, xo + rx2 + 1):
                if (xx, yy) == (xo, yo) or (xx, yy) not in grid:
                    continue
                dn = grid[(xx, yy)][0]
                pen = lam * (gamma * abs(xx - xo) + (1.0 - gamma) * abs(yy - yo))
                if (dn - do) - pen > t:
                    hit = True
        if hit:
            occ[yo, x0] = True
    return occ


def hist_pick(counts: np.ndarray) -> int:
    filled = np.nonzero(counts)[0]
    if filled.size == 256:
        return int(np.argmin(counts))
    if filled.size == 0:
        return 0
    i = np.arange(256)
    dist = np.min(np.abs(i[:, None] - filled[None, :]), axis=1)
    return int(np.argmax(dist))  # first maximum = smallest i


def hist_value(Lo: np.ndarray, Ro: np.ndarray, c: int, r: int, *, cl: int, cr: int, sw: int, sh: int) -> int:
    H, W = Lo.shape[:2]
    y0, y1 = max(0, r - sh // 2), min(H - 1, r + sh // 2)
    counts = np.zeros(256, np.int64)
    for img, cen in ((Lo, cl), (Ro, cr)):
        a, e = max(0, cen - sw // 2), min(W - 1, cen - sw // 2 + sw - 1)
        if a <= e:
            counts += np.bincount(img[y0 : y1 + 1, a : e + 1, c].ravel(), minlength=256)
    return hist_pick(counts)


def ref_project(  # noqa: PLR0912, PLR0915 - a literal transcription of the rules, one step after another
    left: np.ndarray, right: np.ndarray, disp: np.ndarray, cfg: VPPConfig, seed: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Literal projection; returns (left, right, occluded)."""
    Lo = left if left.ndim == 3 else left[:, :, None]
    Ro = right if right.ndim == 3 else right[:, :, None]
    disp = disp.astype(np.float32)
    H, W, C = Lo.shape
    oL = Lo.astype(np.int64).copy()
    oR = Ro.astype(np.int64).copy()
    hmax = (cfg.patch - 1) // 2
    if cfg.occlusion != "off":
        occ = ref_occlusions(disp, (cfg.occ_window_x, cfg.occ_window_y), cfg.occ_lambda, cfg.occ_gamma, cfg.occ_t)
    else:
        occ = np.zeros((H, W), bool)
    pts = sorted(valid_points(disp))  # (d, y, x) global order
    if not pts:
        return Lo.astype(np.uint8).reshape(left.shape), Ro.astype(np.uint8).reshape(right.shape), occ
    ds = [p[0] for p in pts]
    dmin, dmax = min(ds), max(ds)
    if cfg.adaptive_max_disparity is not None:
        dmax = cfg.adaptive_max_disparity
    alpha = cfg.alpha
    wa = w16(alpha)
    neglog = -math.log(cfg.bilateral_threshold)
    two_ss = 2.0 * cfg.bilateral_sigma_space**2
    two_sc = 2.0 * cfg.bilateral_sigma_color**2
    sw, sh = cfg.search_width, cfg.search_height

    def half(d: float) -> int:
        if cfg.adaptive_patch != "distance":
            return hmax
        if dmax <= dmin:
            return hmax
        u = (float(d) - dmin) / (dmax - dmin)
        u = min(max(u, 0.0), 1.0)
        return math.floor(math.pow(u, cfg.adaptive_gamma) * hmax + 0.5)

    def mask(x: int, y: int, dx: int, dy: int) -> bool:
        if not (0 <= x + dx < W and 0 <= y + dy < H):
            return False
        if cfg.adaptive_patch == "bilateral":
            diff = Lo[y + dy, x + dx].astype(np.int64) - Lo[y, x].astype(np.int64)
            sumsq = int((diff * diff).sum())
            e = (dx * dx + dy * dy) / two_ss + (sumsq / C) / two_sc
            return bool(e < neglog)
        return True

    def value(x: int, y: int, d: float, dx: int, dy: int) -> np.ndarray:
        cn = math.floor(x - float(d) + 0.5)
        if cfg.pattern == "random":
            if cfg.uniform_patch:
                return pattern_bytes(seed, x, y, C)
            return pattern_bytes(seed, x + dx, y + dy, C)
        if cfg.uniform_patch:
            return np.array([hist_value(Lo, Ro, c, y, cl=x, cr=cn, sw=sw, sh=sh) for c in range(C)])
        return np.array([hist_value(Lo, Ro, c, y + dy, cl=x + dx, cr=cn + dx, sw=sw, sh=sh) for c in range(C)])

    def is_fgd(y: int, x: int) -> bool:
        return cfg.occlusion == "fgd" and bool(occ[y, x])

    def skipped(y: int, x: int) -> bool:
        return cfg.occlusion == "no" and bool(occ[y, x])

    def patch(d: float, y: int, x: int):
        """The (dx, dy) offsets of the point's patch that are painted, row by row."""
        h = half(d)
        for dy in range(-h, h + 1):
            for dx in range(-h, h + 1):
                if mask(x, y, dx, dy):
                    yield dx, dy

    # right view first, in global order
    for d, y, x in pts:
        if skipped(y, x) or is_fgd(y, x):
            continue
        xp = x - float(d)
        for dx, dy in patch(d, y, x):
            A = value(x, y, d, dx, dy)
            r = y + dy
            if cfg.splat:
                fl = math.floor(xp)
                beta = xp - fl
                targets = [(fl + dx, w16(alpha * (1.0 - beta)))]
                if beta > 0:
                    targets.append((fl + dx + 1, w16(alpha * beta)))
            else:
                targets = [(math.floor(xp + 0.5) + dx, wa)]
            for col, w in targets:
                if 0 <= col < W:
                    for c in range(C):
                        oR[r, col, c] = blend(oR[r, col, c], A[c], w)
    # then the left view (FGD reads the final right view)
    for d, y, x in pts:
        if skipped(y, x):
            continue
        xp = x - float(d)
        for dx, dy in patch(d, y, x):
            r, xl = y + dy, x + dx
            if is_fgd(y, x):
                if cfg.splat:
                    fl = math.floor(xp)
                    beta = xp - fl
                else:
                    fl, beta = math.floor(xp + 0.5), 0.0
                col = fl + dx
                if col < 0 or col >= W or (beta > 0 and col + 1 >= W):
                    continue
                wb = w16(beta)
                for c in range(C):
                    if beta > 0:
                        v16 = int(oR[r, col, c]) * (65536 - wb) + int(oR[r, col + 1, c]) * wb
                    else:
                        v16 = int(oR[r, col, c]) * 65536
                    oL[r, xl, c] = (int(oL[r, xl, c]) * (65536 - wa) * 65536 + v16 * wa + 2**31) >> 32
            else:
                A = value(x, y, d, dx, dy)
                for c in range(C):
                    oL[r, xl, c] = blend(oL[r, xl, c], A[c], wa)
    outL = oL.astype(np.uint8).reshape(left.shape)
    outR = oR.astype(np.uint8).reshape(right.shape)
    return outL, outR, occ
