# distutils: language = c++
"""Row-sweep kernel: point collection, occlusion detection and the default paint, fused.

Used by :func:`vpp_service.vpp.project` for the per-pixel random pattern
(variants (ii) and (vi), any odd patch, any occlusion strategy, with or without
splatting; no adaptive patch) and by :func:`vpp_service.vpp.detect_occlusions`
for every variant (``paint=False``).  Results are byte-identical to the
general kernel (``_kernel.pyx``) and to the literal reference in the tests.

The image is cut into chunks of rows (``prange``, dynamic schedule).  A chunk
walks its rows top to bottom with a small ring of per-row state, so nothing
of size H x W is ever built besides the outputs:

ingest(y)
    scan the disparity row (blocks of 8 zeros are skipped), sort the row's
    keys ``(float_bits(d) << 32) | x`` (positive float bits are monotone, so
    the order is (d, x)), and warp the points into a dense row of the right
    view, ``warp[x - round(d)] = max d`` (``-inf`` elsewhere).
classify(q = y - r_y//2)
    a point is occluded if it lost a collision in its warp cell, or if a
    neighbour of its r_x x r_y window satisfies ``(W_n - d) - pen > t``
    (float64, as in the reference).  Each window row is first bounded with
    its float maximum: since ``pen >= 0`` and rounding is monotone,
    ``(max - d) - pen(|dy|, 0) <= t`` proves no cell of that row qualifies,
    and only the remaining rows are tested cell by cell (exact).
paint(p = q - h)
    copy row p of both inputs to the outputs, merge the sorted keys of rows
    p-h..p+h into the global order (d, y, x) (3x3 and smaller patches: a
    branch-free 3-way merge from both ends, ``_sweep.h``), compute the pattern bytes
    once per contribution, then blend them into the right row and the left row
    (FGD reads the final right row).  Each contribution is at most three
    uniform-weight blends of a K*C-byte span: with splatting, column
    ``floor(x') + dx + 1`` receives ``alpha * beta`` of value ``dx`` *before*
    column ``floor(x') + dx + 1`` receives ``alpha * (1 - beta)`` of value
    ``dx + 1``, so the whole ``beta`` span can be blended first and the whole
    ``1 - beta`` span second.  Spans are blended 16 bytes at a time (SSE2, or
    AVX2 in the x86-64-v3 build ``_sweep_avx2``: see
    :mod:`vpp_service.vpp.backend`), bit-exact with the scalar rule.

A chunk first ingests (and classifies) the few rows above it that its first
rows depend on, so chunks are independent; each output row, statistic and
mask row is written by the chunk that owns the row only, and the result does
not depend on the chunking or the thread count.
"""
from cython.parallel cimport prange, parallel
from libc.stdint cimport uint8_t, uint32_t, uint64_t, int64_t, int32_t
from libc.stdlib cimport malloc, calloc, free, realloc
from libc.string cimport memcpy, memset
from libc.math cimport INFINITY

from vpp_service.vpp._pixel cimport _hash, _seedmix, _w16, _ifloor, _fgd_pixel

import numpy as np


cdef extern from "_sweep.h" nogil:
    int vpp_scan_row(const float* d, int W, uint64_t* keys, int64_t* st)
    void vpp_sort_keys(uint64_t* keys, int n, uint64_t* tmp, int* bucket, int* cnt)
    float vpp_sw_u2f(uint32_t u)
    int vpp_build_avx2()
    int vpp_cpu_supports_avx2()
    int vpp_merge3(const uint64_t* const* l, const uint8_t* const* f, const int* n,
                   const int* base, int32_t* oidx)
    float vpp_maxf(const float* p, int n)
    void vpp_blend_span(uint8_t* dst, const uint8_t* val, int n, uint32_t w, int64_t room)
    int vpp_splat16(uint8_t* dst, const uint8_t* val, int C, int k0, int k1,
                    uint32_t w0, uint32_t w1, int64_t room)
    uint32_t vpp_sw_f2u(float f)

#: True in the build compiled for x86-64-v3 (``_sweep_avx2``), False in the portable one.
AVX2 = bool(vpp_build_avx2())


def cpu_supports_avx2():
    """True when this CPU can run the x86-64-v3 build (checked before importing it)."""
    return bool(vpp_cpu_supports_avx2())


cdef uint64_t ALL1 = 0xFFFFFFFFFFFFFFFFULL
cdef uint64_t LOW32 = 0xFFFFFFFFULL


cdef struct Job:
    # shared, read-only during the sweep (outputs are written row-disjointly)
    const float* disp
    int H
    int W
    int occ_on
    int rx2
    int ry2
    int nwin            # 2 * rx2 + 1
    const double* pen   # (2 ry2 + 1) x nwin, centre = +inf (a point is not its own neighbour)
    const double* penrow  # pen(|dy|, 0), the smallest penalty of window row |dy|
    double t
    uint8_t* occ        # H x W mask
    int64_t* stats      # H x 4: given, valid, invalid, left-border
    int64_t* occ_cnt    # H
    int paint
    const uint8_t* L
    const uint8_t* R
    uint8_t* oL
    uint8_t* oR
    int C
    int hmax
    int splat
    int occmode         # 0 off, 1 no, 2 bkgd, 3 fgd
    double alpha
    uint32_t wa
    uint64_t seedmix
    int ring            # power of two
    int ww              # warp row length
    int woff            # warp index of column 0
    int vs              # value-slot stride (bytes)


cdef struct Scratch:
    uint64_t* keys      # ring x W
    uint8_t* flags      # ring x W (occluded, per key)
    int* nk             # ring
    int* rowid          # ring
    float* warp         # ring x ww
    uint64_t* sort_tmp  # W, scratch of vpp_sort_keys
    int* sort_bucket    # W
    int* sort_cnt       # W + 1
    int64_t cap         # contribution capacity
    int32_t* geo_fl     # ring x W: right-view column floor(x') (or round(x') without splat)
    uint64_t* geo_w     # ring x W: right-view weights w0 | w1 << 32 (1/65536)
    int32_t* cidx       # contributions: ring index of the key, -1 - it if FGD-occluded
    uint8_t* vals       # cap x vs
    uint8_t* zeros      # W + 1 zero flags (occlusion off or bkgd)
    int failed


cdef int _scratch_init(const Job* J, Scratch* S) noexcept nogil:
    cdef int64_t i, nw = <int64_t>J.ring * J.ww
    S.keys = <uint64_t*>malloc(sizeof(uint64_t) * (J.ring * J.W + 1))   # +1: merge read-ahead
    S.geo_fl = <int32_t*>malloc(sizeof(int32_t) * (J.ring * J.W + 1))
    S.geo_w = <uint64_t*>malloc(sizeof(uint64_t) * (J.ring * J.W + 1))
    S.flags = <uint8_t*>malloc(<int64_t>J.ring * J.W + 1)
    S.nk = <int*>malloc(sizeof(int) * J.ring)
    S.rowid = <int*>malloc(sizeof(int) * J.ring)
    S.warp = <float*>malloc(sizeof(float) * (nw if J.occ_on else 1))
    S.sort_tmp = <uint64_t*>malloc(sizeof(uint64_t) * J.W)
    S.sort_bucket = <int*>malloc(sizeof(int) * J.W)
    S.sort_cnt = <int*>malloc(sizeof(int) * (J.W + 1))
    S.zeros = <uint8_t*>calloc(J.W + 1, 1)
    S.cap = 0
    S.cidx = NULL
    S.vals = NULL
    S.failed = 0
    if (S.keys == NULL or S.geo_fl == NULL or S.geo_w == NULL or S.flags == NULL or S.nk == NULL or S.rowid == NULL or S.warp == NULL
            or S.sort_tmp == NULL or S.sort_bucket == NULL or S.sort_cnt == NULL
            or S.zeros == NULL):
        S.failed = 1
        return 1
    for i in range(J.ring):
        S.rowid[i] = -1
        S.nk[i] = 0
    if J.occ_on:
        for i in range(nw):
            S.warp[i] = -INFINITY
    return 0


cdef void _scratch_free(Scratch* S) noexcept nogil:
    free(S.keys)
    free(S.geo_fl)
    free(S.geo_w)
    free(S.flags)
    free(S.nk)
    free(S.rowid)
    free(S.warp)
    free(S.sort_tmp)
    free(S.sort_bucket)
    free(S.sort_cnt)
    free(S.zeros)
    free(S.cidx)
    free(S.vals)


cdef int _reserve(const Job* J, Scratch* S, int64_t n) noexcept nogil:
    cdef int32_t* c
    cdef uint8_t* v
    if n <= S.cap:
        return 0
    n = n + n // 2 + 16
    c = <int32_t*>realloc(S.cidx, sizeof(int32_t) * n)
    if c != NULL:
        S.cidx = c
    v = <uint8_t*>realloc(S.vals, n * J.vs)
    if v != NULL:
        S.vals = v
    if c == NULL or v == NULL:
        S.failed = 1
        return 1
    S.cap = n
    return 0


cdef inline int _xw(uint64_t key) noexcept nogil:
    """Warp column x - round(d) (round half up) of a key."""
    return <int>(key & LOW32) - <int>(<double>vpp_sw_u2f(<uint32_t>(key >> 32)) + 0.5)  # d > 0


cdef void _geometry(const Job* J, const uint64_t* keys, int n, int32_t* fl,
                    uint64_t* w) noexcept nogil:
    """Right-view column and splat weights of each point, once for its 2h+1 patch rows."""
    cdef int i, f
    cdef double xp, beta
    cdef uint64_t w0, w1
    for i in range(n):
        xp = <double>(keys[i] & LOW32) - <double>vpp_sw_u2f(<uint32_t>(keys[i] >> 32))
        if J.splat:
            f = _ifloor(xp)
            beta = xp - <double>f
            w1 = _w16(J.alpha * beta) if beta > 0 else 0
            w0 = _w16(J.alpha * (1.0 - beta))
        else:
            f = _ifloor(xp + 0.5)
            w0 = J.wa
            w1 = 0
        fl[i] = f
        w[i] = w0 | (w1 << 32)


cdef void _ingest(const Job* J, Scratch* S, int y, bint own) noexcept nogil:
    cdef int slot = y & (J.ring - 1)
    cdef int W = J.W
    cdef uint64_t* keys = S.keys + <int64_t>slot * W
    cdef float* wp = S.warp + <int64_t>slot * J.ww + J.woff
    cdef int i, n, xw
    cdef int64_t st[4]
    cdef float d
    if J.occ_on and S.rowid[slot] >= 0:      # clear the evicted row's warp cells
        for i in range(S.nk[slot]):
            wp[_xw(keys[i])] = -INFINITY
    n = vpp_scan_row(J.disp + <int64_t>y * W, W, keys, st)
    vpp_sort_keys(keys, n, S.sort_tmp, S.sort_bucket, S.sort_cnt)
    if own:
        for i in range(4):
            J.stats[<int64_t>y * 4 + i] = st[i]
    S.nk[slot] = n
    S.rowid[slot] = y
    memset(S.flags + <int64_t>slot * W, 0, n)
    if J.paint:
        _geometry(J, keys, n, S.geo_fl + <int64_t>slot * W, S.geo_w + <int64_t>slot * W)
    if J.occ_on:
        for i in range(n):
            xw = _xw(keys[i])
            d = vpp_sw_u2f(<uint32_t>(keys[i] >> 32))
            if d > wp[xw]:
                wp[xw] = d


cdef void _classify(const Job* J, Scratch* S, int q, bint own) noexcept nogil:
    cdef int slot = q & (J.ring - 1)
    cdef int W = J.W, H = J.H, nwin = J.nwin, rx2 = J.rx2, ry2 = J.ry2
    cdef const uint64_t* keys = S.keys + <int64_t>slot * W
    cdef uint8_t* flags = S.flags + <int64_t>slot * W
    cdef const float* wq = S.warp + <int64_t>slot * J.ww + J.woff
    cdef const float* wr
    cdef const double* pr
    cdef int i, n = S.nk[slot], xw, dy, yn, ady, j, found
    cdef int64_t cnt = 0
    cdef float d
    cdef double dd, t = J.t
    for i in range(n):
        d = vpp_sw_u2f(<uint32_t>(keys[i] >> 32))
        dd = d
        xw = _xw(keys[i])
        found = wq[xw] > d                   # lost a collision
        if not found:
            for dy in range(-ry2, ry2 + 1):
                yn = q + dy
                if yn < 0 or yn >= H:
                    continue
                wr = S.warp + <int64_t>(yn & (J.ring - 1)) * J.ww + J.woff + xw - rx2
                ady = dy if dy >= 0 else -dy
                if (<double>vpp_maxf(wr, nwin) - dd) - J.penrow[ady] <= t:
                    continue
                pr = J.pen + <int64_t>(dy + ry2) * nwin
                for j in range(nwin):
                    if (<double>wr[j] - dd) - pr[j] > t:
                        found = 1
                        break
                if found:
                    break
        if found:
            flags[i] = 1
            cnt += 1
            if own:
                J.occ[<int64_t>q * W + <int>(keys[i] & LOW32)] = 1
    if own:
        J.occ_cnt[q] = cnt


cdef inline void _patch_range(int x, int h, int W, int* k0, int* k1) noexcept nogil:
    """Patch pixels [k0, k1) of a point at column x whose left position is inside the image."""
    k0[0] = h - x if x < h else 0
    k1[0] = 2 * h + 1 if x + h < W else W - x + h


cdef inline void _span(const Job* J, uint8_t* row, const uint8_t* vals, int k0, int k1,
                       int base, uint32_t w) noexcept nogil:
    """Blend patch pixels [k0, k1) of ``vals`` into columns base + k of ``row`` (clipped)."""
    cdef int C = J.C, W = J.W
    if -base > k0:
        k0 = -base
    if W - base < k1:
        k1 = W - base
    if k0 < k1:
        vpp_blend_span(row + <int64_t>(base + k0) * C, vals + k0 * C, (k1 - k0) * C, w,
                       <int64_t>(W - base - k0) * C)


cdef void _paint(const Job* J, Scratch* S, int p) noexcept nogil:
    cdef int H = J.H, W = J.W, C = J.C, h = J.hmax, K = 2 * J.hmax + 1
    cdef int64_t rowb = <int64_t>p * W * C
    cdef uint8_t* oL = J.oL + rowb
    cdef uint8_t* oR = J.oR + rowb
    cdef int s_lo, s_hi, nsrc, j, jb, x, k, k0, k1, c, col, fl, slot, n, ncon, idx
    cdef int64_t total
    cdef const uint64_t* src[256]
    cdef const uint8_t* fsrc[256]
    cdef int base[256]
    cdef int head[256]
    cdef int cnt[256]
    cdef uint64_t cand[256]
    cdef uint64_t kb, key, z, wpair
    cdef uint8_t* v
    cdef int occmode = J.occmode, vs = J.vs
    cdef int occ_pt, use_flags
    cdef double xp, beta
    cdef uint32_t w0, w1, wb
    memcpy(oL, J.L + rowb, W * C)
    memcpy(oR, J.R + rowb, W * C)
    s_lo = p - h if p - h > 0 else 0
    s_hi = p + h if p + h < H - 1 else H - 1
    nsrc = s_hi - s_lo + 1
    total = 0
    for j in range(nsrc):
        slot = (s_lo + j) & (J.ring - 1)
        base[j] = slot * W
        src[j] = S.keys + base[j]
        fsrc[j] = S.flags + base[j]
        cnt[j] = S.nk[slot]
        head[j] = 0
        total += cnt[j]
        cand[j] = ((src[j][0] >> 32) << 8) | <uint64_t>j if cnt[j] > 0 else ALL1
    if total == 0:
        return
    if _reserve(J, S, total):
        return
    # 1. merge rows s_lo..s_hi into the global order (d, y, x), ties in d -> smaller row;
    #    cidx = ring index of the key, negative for an occluded point (NO: skipped,
    #    FGD: the right view's content is copied into the left view)
    use_flags = occmode == 1 or occmode == 3
    if nsrc <= 3:
        for j in range(nsrc, 3):
            src[j] = src[0]
            fsrc[j] = fsrc[0]
            base[j] = base[0]
            cnt[j] = 0
        if not use_flags:
            for j in range(3):
                fsrc[j] = S.zeros
        ncon = vpp_merge3(src, fsrc, cnt, base, S.cidx)
    else:
        ncon = 0
        while True:
            kb = cand[0]
            for j in range(1, nsrc):
                kb = cand[j] if cand[j] < kb else kb
            if kb == ALL1:
                break
            jb = <int>(kb & 255)
            k = head[jb]
            head[jb] = k + 1
            cand[jb] = ((src[jb][k + 1] >> 32) << 8) | <uint64_t>jb if k + 1 < cnt[jb] else ALL1
            occ_pt = fsrc[jb][k] if use_flags else 0
            S.cidx[ncon] = base[jb] + k if not occ_pt else -1 - (base[jb] + k)
            ncon += 1
    # 2. pattern bytes of every painted contribution (hash of the left pixel)
    for n in range(ncon):
        idx = S.cidx[n]
        if idx < 0:
            continue
        x = <int>(S.keys[idx] & LOW32)
        _patch_range(x, h, W, &k0, &k1)
        v = S.vals + <int64_t>n * vs
        for k in range(k0, k1):
            z = _hash(J.seedmix, <uint64_t>(x + k - h), <uint64_t>p)
            if C == 3:
                memcpy(v + 3 * k, &z, 4)       # byte 3 is overwritten by pixel k + 1
            else:
                for c in range(C):
                    v[k * C + c] = <uint8_t>(z >> (8 * c))
    # 3. right row: visible contributions, splatted (geometry precomputed at ingest)
    for n in range(ncon):
        idx = S.cidx[n]
        if idx < 0:
            continue
        x = <int>(S.keys[idx] & LOW32)
        _patch_range(x, h, W, &k0, &k1)
        v = S.vals + <int64_t>n * vs
        fl = S.geo_fl[idx]
        wpair = S.geo_w[idx]
        w0 = <uint32_t>(wpair & LOW32)
        w1 = <uint32_t>(wpair >> 32)
        if J.splat:
            if (fl - h < 0 or fl + h + 1 >= W or not vpp_splat16(
                    oR + (fl - h) * C, v, C, k0, k1, w0, w1, <int64_t>(W - fl + h) * C)):
                if w1:
                    _span(J, oR, v, k0, k1, fl - h + 1, w1)
                _span(J, oR, v, k0, k1, fl - h, w0)
        else:
            _span(J, oR, v, k0, k1, fl - h, w0)
    # 4. left row: pattern, or (FGD) the final right row's content at x'
    for n in range(ncon):
        idx = S.cidx[n]
        key = S.keys[idx if idx >= 0 else -1 - idx]
        x = <int>(key & LOW32)
        _patch_range(x, h, W, &k0, &k1)
        if idx >= 0:
            _span(J, oL, S.vals + <int64_t>n * vs, k0, k1, x - h, J.wa)
            continue
        if occmode == 1:
            continue
        xp = <double>x - <double>vpp_sw_u2f(<uint32_t>(key >> 32))
        if J.splat:
            fl = _ifloor(xp)
            beta = xp - <double>fl
        else:
            fl = _ifloor(xp + 0.5)
            beta = 0.0
        wb = <uint32_t>_w16(beta)
        for k in range(k0, k1):
            col = fl + k - h
            if col < 0 or col >= W or (beta > 0 and col + 1 >= W):
                continue
            _fgd_pixel(oL + (x + k - h) * C, oR + col * C, C, beta > 0, wb, J.wa)


cdef void _run_chunk(const Job* J, Scratch* S, int c0, int c1) noexcept nogil:
    """Paint (or classify) rows [c0, c1), ingesting the rows they depend on."""
    cdef int h = J.hmax if J.paint else 0
    cdef int ry2 = J.ry2 if J.occ_on else 0
    cdef int H = J.H
    cdef int y0 = c0 - h - ry2
    cdef int cl0 = c0 - h, cl1 = c1 - 1 + h
    cdef int t, q, p
    if y0 < 0:
        y0 = 0
    if cl0 < 0:
        cl0 = 0
    if cl1 > H - 1:
        cl1 = H - 1
    for t in range(y0, c1 + h + ry2):
        if S.failed:
            return
        if t < H:
            _ingest(J, S, t, t >= c0 and t < c1)
        q = t - ry2
        if J.occ_on and q >= cl0 and q <= cl1:
            _classify(J, S, q, q >= c0 and q < c1)
        p = q - h
        if J.paint and p >= c0 and p < c1:
            _paint(J, S, p)


def sweep_kernel(const float[:, ::1] disp, uint8_t[:, ::1] occ, bint occ_on, int rx, int ry,
                 double[:, ::1] pen, double t,
                 const uint8_t[:, :, ::1] left, const uint8_t[:, :, ::1] right,
                 uint8_t[:, :, ::1] out_left, uint8_t[:, :, ::1] out_right,
                 bint paint, int hmax, double alpha, bint splat, int occmode,
                 uint64_t seed, int nthreads):
    """Run the sweep.  ``pen`` is the ``[|dy|, |dx|]`` penalty table; ``paint``
    false only classifies (the image arguments are then ignored and may be
    1 x 1 x 1).  Returns ``(row stats H x 4, occluded per row)``."""
    cdef int H = disp.shape[0], W = disp.shape[1]
    cdef int rx2 = rx // 2, ry2 = ry // 2
    cdef int nwin = 2 * rx2 + 1, i, j, need, ci, nchunks, chunk
    cdef Job J
    cdef Scratch* S = NULL
    failed_np = np.zeros(1, np.int32)
    cdef int32_t[::1] failed = failed_np
    stats = np.zeros((H, 4), np.int64)
    cnt = np.zeros(H, np.int64)
    pen_full = np.empty((2 * ry2 + 1, nwin), np.float64)
    for j in range(2 * ry2 + 1):
        for i in range(nwin):
            pen_full[j, i] = pen[abs(j - ry2), abs(i - rx2)]
    pen_full[ry2, rx2] = np.inf
    penrow = np.ascontiguousarray(np.asarray(pen)[:, 0])
    cdef double[:, ::1] pf = pen_full
    cdef double[::1] prow = penrow
    cdef int64_t[:, ::1] st = stats
    cdef int64_t[::1] cn = cnt
    if H == 0 or W == 0:
        return stats, cnt
    J.disp = &disp[0, 0]
    J.H = H
    J.W = W
    J.occ_on = occ_on
    J.rx2 = rx2
    J.ry2 = ry2
    J.nwin = nwin
    J.pen = &pf[0, 0]
    J.penrow = &prow[0]
    J.t = t
    J.occ = &occ[0, 0]
    J.stats = &st[0, 0]
    J.occ_cnt = &cn[0]
    J.paint = paint
    J.L = &left[0, 0, 0]
    J.R = &right[0, 0, 0]
    J.oL = &out_left[0, 0, 0]
    J.oR = &out_right[0, 0, 0]
    J.C = left.shape[2]
    J.hmax = hmax if paint else 0
    J.splat = splat
    J.occmode = occmode
    J.alpha = alpha
    J.wa = <uint32_t>_w16(alpha)
    J.seedmix = _seedmix(seed)
    need = 2 * J.hmax + 1
    if occ_on:
        need = max(need, ry2 + 2 * J.hmax + 1, 2 * ry2 + 1)
    J.ring = 1
    while J.ring < need:
        J.ring *= 2
    J.ww = 2 * W + 2 * rx2 + 8       # warp columns -W .. W-1, +- rx2, SIMD over-read
    J.woff = W + rx2
    J.vs = (((2 * J.hmax + 1) * J.C + 15) & ~15) + 16
    if nthreads <= 1:
        nchunks = 1
    else:
        nchunks = min(H, 4 * nthreads)
    chunk = (H + nchunks - 1) // nchunks
    nchunks = (H + chunk - 1) // chunk
    with nogil, parallel(num_threads=nthreads):
        S = <Scratch*>malloc(sizeof(Scratch))
        if S != NULL:
            _scratch_init(&J, S)
        for ci in prange(nchunks, schedule="dynamic"):
            if S == NULL or S.failed:
                failed[0] = 1
            else:
                _run_chunk(&J, S, ci * chunk, min(H, ci * chunk + chunk))
        if S != NULL:
            if S.failed:
                failed[0] = 1
            _scratch_free(S)
            free(S)
    if failed[0]:
        raise MemoryError("VPP sweep: out of memory for the per-thread buffers")
    return stats, cnt
