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
    scan the disparity row (SIMD compare + compress, no branches) into keys
    ``(float_bits(d) << 32) | x`` in increasing x, compute each point's
    right-view column and splat weights once, and warp the points into a dense
    row of the right view, ``warp[x - round(d)] = max d`` (``-inf`` elsewhere).
    The warp keeps the window's rows in a ring of ``wring`` slots stored
    column-major: one column's rows are one vector.
classify(q = y - r_y//2)
    a point is occluded if it lost a collision in its warp cell, or if a
    neighbour of its r_x x r_y window satisfies ``(W_n - d) - pen > t``
    (float64, as in the reference).  The window is first screened in float,
    one vector per window column, against ``d + t`` lowered by a margin larger
    than the float rounding, so the screen never misses a cell the exact rule
    flags; only points with a passing cell are tested cell by cell (exact).
paint a band of 16 rows [b0, b1) once rows up to b1 - 1 + h are classified
    copy the band's rows of both inputs to the outputs; gather the points of
    rows b0-h .. b1-1+h in (row, x) order and sort them stably by d -- the
    global order (d, y, x) -- with a linear-time bucket sort;
    then each point paints the band rows its patch covers: pattern bytes (the
    hash of each left pixel) and the splatted right view for every point
    first, then the left view (FGD reads the final right rows).  Each patch row
    is at most three uniform-weight blends of a K*C-byte span: with
    splatting, column ``floor(x') + dx + 1`` receives ``alpha * beta`` of value
    ``dx`` *before* it receives ``alpha * (1 - beta)`` of value ``dx + 1``, so
    the whole ``beta`` span can be blended first and the whole ``1 - beta``
    span second (one 16-byte vector for 3x3 RGB).  Spans are blended 16 bytes
    at a time (SSE2, or AVX2 in the x86-64-v3 build ``_sweep_avx2``: see
    :mod:`vpp_service.vpp.backend`), bit-exact with the scalar rule.

A chunk first ingests (and classifies) the few rows above it that its first
rows depend on, so chunks are independent; each output row, statistic and
mask row is written by the chunk that owns the row only, and the result does
not depend on the chunking or the thread count.
"""
from cython.parallel cimport prange, parallel
from libc.stdint cimport uint8_t, uint32_t, uint64_t, int64_t, int32_t, uintptr_t
from libc.stdlib cimport calloc, malloc, free
from libc.string cimport memcpy, memset
from libc.math cimport INFINITY

from vpp_service.vpp._pixel cimport _hash, _seedmix, _pidx, _w16, _ifloor, _fgd_pixel, PAT_ROW_STEP, PAT_MASK

import numpy as np


cdef extern from "_sweep.h" nogil:
    int vpp_scan_row_w(const float* d, int W, uint64_t* keys, int64_t* st)
    void vpp_scan_init()
    ctypedef struct BandPt "vpp_band_pt":
        # one point of a band, in gather order (compact: read in d order by the passes)
        int32_t x
        int32_t s           # image row
        int32_t fl          # right-view column (see vpp_geometry)
        uint32_t w0
        uint32_t w1
        int32_t occl        # FGD-occluded
        float d
    void vpp_sort_band(const BandPt* pts, const float* dv, int n, float dmin, float dmax,
                       BandPt* out, int* bucket, int* cnt)
    float vpp_sw_u2f(uint32_t u)
    int vpp_build_avx2()
    int vpp_cpu_supports_avx2()
    void vpp_occ_screen(const uint64_t* keys, const int32_t* xw, int n, const float* warp0, int WL, int lq,
                        const float* pv, int nwin, int rx2, double t, double penmax, uint8_t* out)
    void vpp_blend_span(uint8_t* dst, const uint8_t* val, int n, uint32_t w, int64_t room)
    int vpp_splat16(uint8_t* dst, const uint8_t* val, int C, int k0, int k1,
                    uint32_t w0, uint32_t w1, int64_t room)
    uint32_t vpp_sw_f2u(float f)
    void vpp_splat_rows_avx2(uint8_t* dst, int64_t rs, const uint8_t* pat, int64_t p0, int64_t step,
                             int64_t mask, int nrows, int C, int k0, int k1, uint32_t w0, uint32_t w1)
    void vpp_blend_rows_avx2(uint8_t* dst, int64_t rs, const uint8_t* pat, int64_t p0, int64_t step,
                             int64_t mask, int nrows, int C, int lo, int hi, uint32_t w)
    void vpp_geometry(const uint64_t* keys, int n, int32_t* xw, int32_t* fl, uint64_t* w,
                      int splat, double alpha, uint32_t wa)

vpp_scan_init()     # the scan's compress table, once per process (before any sweep)

#: True in the build compiled for x86-64-v3 (``_sweep_avx2``), False in the portable one.
AVX2 = bool(vpp_build_avx2())


def cpu_supports_avx2():
    """True when this CPU can run the x86-64-v3 build (checked before importing it)."""
    return bool(vpp_cpu_supports_avx2())


cdef uint64_t LOW32 = 0xFFFFFFFFULL

#: pattern-table entries per seed and row step of the index (``_pidx``; tested equal to ``rng``'s)
TABLE_SIZE = PAT_MASK + 1
ROW_STEP = PAT_ROW_STEP


def table_padding(int C, int hmax):
    """Bytes the kernels may read past the ``TABLE_SIZE * C`` bytes of a table:
    a patch row (``2 hmax + 1`` pixels) starting at the last entry, plus SIMD over-read."""
    return (2 * hmax + 1) * C + 64


def fill_pattern_table(uint64_t seed, uint8_t[::1] out, int C):
    """Write the seed's pattern table for ``C`` channels (``rng.pattern_table``) into
    ``out[:TABLE_SIZE * C]`` and repeat its start over the rest of ``out`` (the padding)."""
    cdef int64_t core = <int64_t>TABLE_SIZE * C, n = out.shape[0], i, j, b
    cdef uint64_t sm = _seedmix(seed), z
    if C < 1 or n < core:
        raise ValueError(f"out has {n} bytes, need at least {core} for {C} channel(s)")
    with nogil:
        for j in range((core + 7) // 8):
            z = _hash(sm, <uint64_t>(j + 1), 0)
            for b in range(8):
                if 8 * j + b < core:
                    out[8 * j + b] = <uint8_t>(z >> (8 * b))
        for i in range(core, n):
            out[i] = out[i - core]


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
    double penmax       # largest finite penalty
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
    const uint8_t* pat  # padded pattern table (rng.py): a patch row is one span of it
    int ring            # power of two: rows of keys, flags and geometry kept
    int wring           # power of two >= 2 ry2 + 1: warp rows kept (a smaller ring: less cache)
    int band            # output rows painted together
    int ww              # warp columns (-W - rx2 .. W - 1 + rx2)
    int woff            # warp column index of image column 0


cdef struct Scratch:
    uint64_t* keys      # ring x W
    uint8_t* flags      # ring x W (occluded, per key)
    int* nk             # ring
    float* warp_mem     # allocation of warp (aligned to 64 bytes in it)
    float* warp         # ww columns x wring slots, column-major: the window's rows
                        # of one column are one vector (see _ingest, _classify)
    int* wrowid         # wring: the row each slot holds (-1: none)
    int32_t* xw         # ring x W: warp column x - round(d) per key
    float* pvec         # nwin x wring: the current row's float penalty per (column, slot), +inf off the window
    int* dyl            # wring: each slot's row offset from the classified row (ry2 + 1: not in the window)
    int64_t cap         # contribution capacity
    int32_t* geo_fl     # ring x W: right-view column floor(x') (or round(x') without splat)
    uint64_t* geo_w     # ring x W: right-view weights w0 | w1 << 32 (1/65536)
    BandPt* bpt         # band points in gather order (row, x)
    BandPt* spt         # in paint order (d, y, x)
    float* bd           # their d in gather order (cap)
    int* bbucket        # sort scratch: bucket ids (cap) and counts (below)
    int* bcnt           # 2 cap + 1
    int failed
    int64_t kcap        # capacity (entries) of keys, geo_fl, geo_w, xw, flags
    int64_t wcap        # of warp
    int rcap            # of nk
    int wrcap           # of wrowid
    int ecap            # of pvec (entries)


cdef int _scratch_init(const Job* J, Scratch* S) noexcept nogil:
    """Size ``S`` for ``J`` (reusing its buffers when large enough: a pooled
    Scratch comes back with the capacities of its last job) and reset its state."""
    cdef int64_t i, nw = <int64_t>J.wring * J.ww if J.occ_on else 1
    cdef int64_t nk = <int64_t>J.ring * J.W + 1
    cdef int ne = J.nwin * J.wring
    S.failed = 0
    if nk > S.kcap:
        free(S.keys)
        free(S.geo_fl)
        free(S.geo_w)
        free(S.xw)
        free(S.flags)
        S.keys = <uint64_t*>malloc(sizeof(uint64_t) * nk)
        S.geo_fl = <int32_t*>malloc(sizeof(int32_t) * nk)
        S.geo_w = <uint64_t*>malloc(sizeof(uint64_t) * nk)
        S.xw = <int32_t*>malloc(sizeof(int32_t) * nk)
        S.flags = <uint8_t*>malloc(nk)
        S.kcap = nk
        if S.keys == NULL or S.geo_fl == NULL or S.geo_w == NULL or S.xw == NULL or S.flags == NULL:
            S.kcap = 0
            S.failed = 1
    if ne > S.ecap:
        free(S.pvec)
        S.pvec = <float*>malloc(sizeof(float) * ne)
        S.ecap = ne
        if S.pvec == NULL:
            S.ecap = 0
            S.failed = 1
    if J.ring > S.rcap:
        free(S.nk)
        S.nk = <int*>malloc(sizeof(int) * J.ring)
        S.rcap = J.ring
        if S.nk == NULL:
            S.rcap = 0
            S.failed = 1
    if J.wring > S.wrcap:
        free(S.wrowid)
        free(S.dyl)
        S.wrowid = <int*>malloc(sizeof(int) * J.wring)
        S.dyl = <int*>malloc(sizeof(int) * J.wring)
        S.wrcap = J.wring
        if S.wrowid == NULL or S.dyl == NULL:
            S.wrcap = 0
            S.failed = 1
    if nw > S.wcap:
        free(S.warp_mem)
        S.warp_mem = <float*>malloc(sizeof(float) * nw + 64)
        S.warp = <float*>((<uintptr_t>S.warp_mem + 63) & ~(<uintptr_t>63))
        S.wcap = nw if S.warp_mem != NULL else 0
        if S.warp_mem == NULL:
            S.failed = 1
    if S.failed:
        return 1
    for i in range(J.ring):
        S.nk[i] = 0
    for i in range(J.wring):
        S.wrowid[i] = -1
    if J.occ_on:
        for i in range(nw):
            S.warp[i] = -INFINITY
    return 0


cdef void _scratch_free(Scratch* S) noexcept nogil:
    free(S.keys)
    free(S.geo_fl)
    free(S.geo_w)
    free(S.xw)
    free(S.pvec)
    free(S.dyl)
    free(S.flags)
    free(S.nk)
    free(S.warp_mem)
    free(S.wrowid)
    _free_band(S)


cdef extern from *:
    """
    #include <atomic>
    #define VPP_POOL 64
    /* Scratch buffers kept between calls: each one is a few MB that, freshly
       mapped every call, cost a page fault per 4 KiB (about 9 % of the kernel). */
    static std::atomic<void*> vpp_scratch_pool[VPP_POOL];
    static void* vpp_pool_take(void) {
        for (int i = 0; i < VPP_POOL; i++) {
            void* s = vpp_scratch_pool[i].exchange(nullptr, std::memory_order_acq_rel);
            if (s) return s;
        }
        return nullptr;
    }
    static int vpp_pool_give(void* s) {
        for (int i = 0; i < VPP_POOL; i++) {
            void* expected = nullptr;
            if (vpp_scratch_pool[i].compare_exchange_strong(expected, s, std::memory_order_acq_rel))
                return 1;
        }
        return 0;
    }
    """
    void* vpp_pool_take() nogil
    int vpp_pool_give(void* s) nogil


cdef Scratch* _scratch_take() noexcept nogil:
    """A pooled Scratch (buffers of an earlier job), else a new empty one (NULL if out of memory)."""
    cdef Scratch* S = <Scratch*>vpp_pool_take()
    if S == NULL:
        S = <Scratch*>calloc(1, sizeof(Scratch))
    return S


cdef void _scratch_give(Scratch* S) noexcept nogil:
    """Return ``S`` to the pool (freed instead when it failed or the pool is full)."""
    if S.failed or not vpp_pool_give(S):
        _scratch_free(S)
        free(S)


def release_scratch():
    """Free the per-thread scratch buffers kept between calls (a few MB per thread
    for the largest image seen); the next call allocates them again.  Returns
    how many were freed."""
    cdef int n = 0
    cdef Scratch* S
    with nogil:
        S = <Scratch*>vpp_pool_take()
        while S != NULL:
            _scratch_free(S)
            free(S)
            n += 1
            S = <Scratch*>vpp_pool_take()
    return n


cdef void _free_band(Scratch* S) noexcept nogil:
    free(S.bpt)
    free(S.spt)
    free(S.bd)
    free(S.bbucket)
    free(S.bcnt)


cdef int _reserve(const Job* J, Scratch* S, int64_t n) noexcept nogil:
    """Grow the band buffers to hold n points."""
    if n <= S.cap:
        return 0
    n = n + n // 2 + 16
    _free_band(S)
    S.bpt = <BandPt*>malloc(sizeof(BandPt) * n)
    S.spt = <BandPt*>malloc(sizeof(BandPt) * n)
    S.bd = <float*>malloc(sizeof(float) * n)
    S.bbucket = <int*>malloc(sizeof(int) * n)
    S.bcnt = <int*>malloc(sizeof(int) * (2 * n + 1))
    if S.bpt == NULL or S.spt == NULL or S.bd == NULL or S.bbucket == NULL or S.bcnt == NULL:
        S.cap = 0
        S.failed = 1
        return 1
    S.cap = n
    return 0


cdef void _ingest(const Job* J, Scratch* S, int y, bint own) noexcept nogil:
    cdef int slot = y & (J.ring - 1)
    cdef int W = J.W
    cdef uint64_t* keys = S.keys + <int64_t>slot * W
    cdef int32_t* xw = S.xw + <int64_t>slot * W
    cdef int ws = y & (J.wring - 1)
    cdef float* wp = S.warp + <int64_t>J.woff * J.wring + ws    # column 0 of slot ws
    cdef int64_t WL = J.wring
    cdef int i, n, yo, ko
    cdef int64_t st[4]
    cdef float d
    cdef const int32_t* xo
    if J.occ_on:
        # clear the warp cells of the row this warp row held, from that row's keys:
        # they are still in the key ring, because ring is a multiple of wring (both
        # powers of two), so the row that takes over its key slot takes over its
        # warp row too, and clears it first (here)
        yo = S.wrowid[ws]
        if yo >= 0:
            ko = yo & (J.ring - 1)
            xo = S.xw + <int64_t>ko * W
            for i in range(S.nk[ko]):
                wp[xo[i] * WL] = -INFINITY
        S.wrowid[ws] = y
    n = vpp_scan_row_w(J.disp + <int64_t>y * W, W, keys, st)   # in increasing x
    if own:
        for i in range(4):
            J.stats[<int64_t>y * 4 + i] = st[i]
        memset(J.occ + <int64_t>y * W, 0, W)   # the mask row (first touched by this thread)
    S.nk[slot] = n
    memset(S.flags + <int64_t>slot * W, 0, n)
    # warp columns (occlusion) and right-view column + splat weights (paint), once per point
    vpp_geometry(keys, n, xw if J.occ_on else NULL,
                 S.geo_fl + <int64_t>slot * W if J.paint else NULL, S.geo_w + <int64_t>slot * W,
                 J.splat, J.alpha, J.wa)
    if J.occ_on:
        for i in range(n):
            d = vpp_sw_u2f(<uint32_t>(keys[i] >> 32))
            if d > wp[xw[i] * WL]:
                wp[xw[i] * WL] = d


cdef void _classify(const Job* J, Scratch* S, int q, bint own) noexcept nogil:
    """Occlusion flags of row q's points.  The warp is column-major: a column's
    ``wring`` slots hold the window's rows (slot ``y & (wring - 1)``), so one
    vector per window column holds all its rows; ``pvec`` gives each (column,
    slot) its float penalty for row q, +inf for slots outside the window (or
    rows not ingested) and for the point's own cell.  The window is first
    screened in float (``vpp_occ_screen`` in _sweep.h: a margin makes sure the
    screen never misses a cell the exact rule flags); only points with a
    passing cell are checked exactly (in double, as the reference)."""
    cdef int slot = q & (J.ring - 1)
    cdef int W = J.W, nwin = J.nwin, rx2 = J.rx2, ry2 = J.ry2, WL = J.wring
    cdef const uint64_t* keys = S.keys + <int64_t>slot * W
    cdef const int32_t* xws = S.xw + <int64_t>slot * W
    cdef uint8_t* flags = S.flags + <int64_t>slot * W
    cdef const float* warp0 = S.warp + <int64_t>J.woff * WL     # column 0
    cdef const float* col
    cdef int i, n = S.nk[slot], xw, dy, j, L, found, yo
    cdef int64_t cnt = 0
    cdef double dd, t = J.t
    for L in range(WL):                       # each slot's row offset, and its penalties
        yo = S.wrowid[L]
        dy = yo - q if yo >= 0 else ry2 + 1
        if dy < -ry2 or dy > ry2:
            dy = ry2 + 1
        S.dyl[L] = dy
        for j in range(nwin):
            S.pvec[j * WL + L] = <float>J.pen[(dy + ry2) * nwin + j] if dy <= ry2 else INFINITY
    # flags: 1 lost a collision, 2 a window candidate, 0 visible
    vpp_occ_screen(keys, xws, n, warp0, WL, q & (WL - 1), S.pvec, nwin, rx2, t, J.penmax, flags)
    for i in range(n):
        found = flags[i]
        if found == 0:
            continue
        if found == 2:
            found = 0
            dd = vpp_sw_u2f(<uint32_t>(keys[i] >> 32))
            xw = xws[i]
            for j in range(nwin):
                col = warp0 + <int64_t>(xw - rx2 + j) * WL
                for L in range(WL):
                    dy = S.dyl[L]
                    if dy <= ry2 and (<double>col[L] - dd) - J.pen[(dy + ry2) * nwin + j] > t:
                        found = 1
                        break
                if found:
                    break
            flags[i] = found
            if not found:
                continue
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


cdef void _paint_band(const Job* J, Scratch* S, int b0, int b1) noexcept nogil:
    """Paint output rows [b0, b1): every point of rows b0-h .. b1-1+h, in the global
    order (d, y, x), blended into the band rows it covers (right view, then left)."""
    cdef int H = J.H, W = J.W, C = J.C, h = J.hmax, K = 2 * J.hmax + 1
    cdef int64_t rs = <int64_t>W * C
    cdef int s0 = b0 - h if b0 - h > 0 else 0
    cdef int s1 = b1 - 1 + h if b1 - 1 + h < H - 1 else H - 1
    cdef int occmode = J.occmode
    cdef int use_flags = occmode == 1 or occmode == 3
    # one vector per patch row (AVX2 build, C in {1, 3}, the patch plus a splat column within 16 bytes)
    cdef int rows_fast = vpp_build_avx2() and (C == 1 or C == 3) and (K + 1) * C <= 16
    cdef int s, slot, i, j, m, x, r, r0, r1, k0, k1, k, c, fl, flag, base
    cdef BandPt* pt
    cdef int64_t total = 0
    cdef uint64_t key, wpair
    cdef const uint8_t* v
    cdef uint8_t* oL
    cdef uint8_t* oR
    cdef uint32_t w0, w1, wb
    cdef double xp, beta
    cdef float d, dmin, dmax
    for r in range(b0, b1):
        memcpy(J.oL + r * rs, J.L + r * rs, rs)
        memcpy(J.oR + r * rs, J.R + r * rs, rs)
    for s in range(s0, s1 + 1):
        total += S.nk[s & (J.ring - 1)]
    if total == 0:
        return
    if _reserve(J, S, total):
        return
    # 1. gather the points in (row, x) order and sort them stably by d: the global
    #    order (d, y, x); NO-occluded points are dropped here
    m = 0
    dmin = INFINITY
    dmax = -INFINITY
    for s in range(s0, s1 + 1):
        slot = s & (J.ring - 1)
        base = slot * W
        for i in range(S.nk[slot]):
            flag = S.flags[base + i] if use_flags else 0
            if flag and occmode == 1:
                continue
            key = S.keys[base + i]
            pt = &S.bpt[m]
            pt.x = <int32_t>(key & LOW32)
            pt.s = s
            pt.fl = S.geo_fl[base + i]
            wpair = S.geo_w[base + i]
            pt.w0 = <uint32_t>(wpair & LOW32)
            pt.w1 = <uint32_t>(wpair >> 32)
            pt.occl = flag
            d = vpp_sw_u2f(<uint32_t>(key >> 32))
            pt.d = d
            S.bd[m] = d
            dmin = d if d < dmin else dmin
            dmax = d if d > dmax else dmax
            m += 1
    # into paint order once: both passes then read sequentially
    vpp_sort_band(S.bpt, S.bd, m, dmin, dmax, S.spt, S.bbucket, S.bcnt)
    # 2. right view: each visible point's pattern span per covered band row (read
    #    in place from the table), splatted; geometry was computed at ingest
    for j in range(m):
        pt = &S.spt[j]
        if pt.occl:
            continue
        s = pt.s
        x = pt.x
        _patch_range(x, h, W, &k0, &k1)
        fl = pt.fl
        w0 = pt.w0
        w1 = pt.w1
        r0 = s - h if s - h > b0 else b0
        r1 = s + h if s + h < b1 - 1 else b1 - 1
        if rows_fast and fl - h >= 0 and fl + h + 1 < W and <int64_t>(W - fl + h) * C >= 16:
            # the whole patch column at once: weights and lane masks set up once
            if J.splat:
                vpp_splat_rows_avx2(J.oR + r0 * rs + (fl - h) * C, rs, J.pat, x - h + <int64_t>r0 * PAT_ROW_STEP,
                                    PAT_ROW_STEP, PAT_MASK, r1 - r0 + 1, C, k0, k1, w0, w1)
            else:
                vpp_blend_rows_avx2(J.oR + r0 * rs + (fl - h) * C, rs, J.pat, x - h + <int64_t>r0 * PAT_ROW_STEP,
                                    PAT_ROW_STEP, PAT_MASK, r1 - r0 + 1, C, k0 * C, k1 * C, w0)
            continue
        for r in range(r0, r1 + 1):
            v = J.pat + _pidx(x - h, r) * C
            oR = J.oR + r * rs
            if J.splat:
                if (fl - h < 0 or fl + h + 1 >= W or not vpp_splat16(
                        oR + (fl - h) * C, v, C, k0, k1, w0, w1, <int64_t>(W - fl + h) * C)):
                    if w1:
                        _span(J, oR, v, k0, k1, fl - h + 1, w1)
                    _span(J, oR, v, k0, k1, fl - h, w0)
            else:
                _span(J, oR, v, k0, k1, fl - h, w0)
    # 3. left view: the pattern, or (FGD) the final right row's content at x'
    for j in range(m):
        pt = &S.spt[j]
        s = pt.s
        x = pt.x
        _patch_range(x, h, W, &k0, &k1)
        r0 = s - h if s - h > b0 else b0
        r1 = s + h if s + h < b1 - 1 else b1 - 1
        if not pt.occl:
            if rows_fast and x - h >= 0 and <int64_t>(W - x + h) * C >= 16:
                vpp_blend_rows_avx2(J.oL + r0 * rs + (x - h) * C, rs, J.pat, x - h + <int64_t>r0 * PAT_ROW_STEP,
                                    PAT_ROW_STEP, PAT_MASK, r1 - r0 + 1, C, k0 * C, k1 * C, J.wa)
                continue
            for r in range(r0, r1 + 1):
                _span(J, J.oL + r * rs, J.pat + _pidx(x - h, r) * C, k0, k1, x - h, J.wa)
            continue
        xp = <double>x - <double>pt.d
        if J.splat:
            fl = _ifloor(xp)
            beta = xp - <double>fl
        else:
            fl = _ifloor(xp + 0.5)
            beta = 0.0
        wb = <uint32_t>_w16(beta)
        for r in range(r0, r1 + 1):
            oL = J.oL + r * rs
            oR = J.oR + r * rs
            for k in range(k0, k1):
                c = fl + k - h
                if c < 0 or c >= W or (beta > 0 and c + 1 >= W):
                    continue
                _fgd_pixel(oL + (x + k - h) * C, oR + c * C, C, beta > 0, wb, J.wa)


cdef void _run_chunk(const Job* J, Scratch* S, int c0, int c1) noexcept nogil:
    """Paint (or classify) rows [c0, c1), ingesting the rows they depend on."""
    cdef int h = J.hmax if J.paint else 0
    cdef int ry2 = J.ry2 if J.occ_on else 0
    cdef int H = J.H
    cdef int y0 = c0 - h - ry2
    cdef int cl0 = c0 - h, cl1 = c1 - 1 + h
    cdef int t, q, p, b0 = c0
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
        p = q - h                   # rows up to p are ready to paint
        if J.paint and p >= c0 and p < c1 and (p + 1 - b0 == J.band or p == c1 - 1):
            _paint_band(J, S, b0, p + 1)
            b0 = p + 1


def sweep_kernel(const float[:, ::1] disp, uint8_t[:, ::1] occ, bint occ_on, int rx, int ry,
                 double[:, ::1] pen, double t,
                 const uint8_t[:, :, ::1] left, const uint8_t[:, :, ::1] right,
                 uint8_t[:, :, ::1] out_left, uint8_t[:, :, ::1] out_right,
                 bint paint, int hmax, double alpha, bint splat, int occmode,
                 const uint8_t[::1] pattern, int nthreads):
    """Run the sweep.  ``pen`` is the ``[|dy|, |dx|]`` penalty table; ``paint``
    false only classifies (the image arguments are then ignored and may be
    1 x 1 x 1, and ``pattern`` may be empty).  ``pattern`` is the seed's table
    padded by ``table_padding(C, hmax)`` bytes (:func:`fill_pattern_table`).
    Returns ``(row stats H x 4, occluded per row)``."""
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
    cdef double[:, ::1] pf = pen_full
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
    J.penmax = float(pen_full[np.isfinite(pen_full)].max(initial=0.0))
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
    if paint and pattern.shape[0] < TABLE_SIZE * J.C + table_padding(J.C, J.hmax):
        raise ValueError(f"pattern table has {pattern.shape[0]} bytes, need "
                         f"{TABLE_SIZE * J.C + table_padding(J.C, J.hmax)}")
    J.pat = &pattern[0] if paint else NULL
    J.band = 16 if paint else 1
    # rows alive at once: a band and its patch margins, plus the occlusion window lag
    need = J.band + 2 * J.hmax
    if occ_on:
        need = max(need + ry2, 2 * ry2 + 1)
    J.ring = 1
    while J.ring < need:
        J.ring *= 2
    J.wring = 1                      # <= ring (need >= 2 ry2 + 1 when occ_on)
    while J.wring < 2 * ry2 + 1:
        J.wring *= 2
    J.ww = 2 * W + 2 * rx2           # warp columns -W - rx2 .. W - 1 + rx2
    J.woff = W + rx2
    if nthreads <= 1:
        nchunks = 1
    else:
        nchunks = min(H, 4 * nthreads)
    chunk = (H + nchunks - 1) // nchunks
    nchunks = (H + chunk - 1) // chunk
    with nogil, parallel(num_threads=nthreads):
        S = _scratch_take()
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
            _scratch_give(S)
    if failed[0]:
        raise MemoryError("VPP sweep: out of memory for the per-thread buffers")
    return stats, cnt
