# distutils: language = c++
"""The VPP kernel: one row sweep that collects the points, detects occlusions and paints.

:func:`paint` serves every variant of :class:`~vpp_service.vpp.VPPConfig`;
:func:`occlusions` only classifies.  Both take the parameter dict of
:func:`vpp_service.vpp.params.kernel_params`.  The rules are those of the
literal reference ``tests/vpp_reference.py``; results are byte-identical to it
for any thread count.  This source is compiled twice (``_sweep`` portable,
``_sweep_avx2`` for x86-64-v3; :mod:`vpp_service.vpp.backend` picks one); the
C in ``_sweep.h`` chooses its SIMD code at compile time.

Rows are processed in chunks (``prange``); a chunk walks its rows with a small
ring of per-row state: *ingest* a row (scan, geometry, warp), *classify* the
row ``r_y // 2`` above (occlusion), and *paint* bands of 16 rows once the rows
their patches reach are classified (gather the points with their patch
half-size, fill the band's value source, sort by d, blend the right view, then
the left view).  ``docs/algorithm.md`` ("The kernel") describes each step.
"""
from cython.parallel cimport prange, parallel
from libc.stdint cimport uint8_t, uint32_t, uint64_t, int64_t, int32_t, int16_t, uintptr_t
from libc.stdlib cimport calloc, malloc, free
from libc.string cimport memcpy, memset
from libc.math cimport INFINITY, floor, pow

import numpy as np


cdef extern from "_sweep.h" nogil:
    cpdef enum Pattern "vpp_pattern":
        RANDOM "VPP_PATTERN_RANDOM"
        HISTOGRAM "VPP_PATTERN_HISTOGRAM"
    cpdef enum Occlusion "vpp_occlusion":
        OCC_OFF "VPP_OCC_OFF"
        OCC_NO "VPP_OCC_NO"
        OCC_BKGD "VPP_OCC_BKGD"
        OCC_FGD "VPP_OCC_FGD"
    cpdef enum PatchMask "vpp_patch_mask":
        MASK_FULL "VPP_MASK_FULL"
        MASK_DISTANCE "VPP_MASK_DISTANCE"
        MASK_BILATERAL "VPP_MASK_BILATERAL"
    enum:
        VPP_ROW_STEP
        VPP_TABLE_MASK
    ctypedef struct BandPt "vpp_band_pt":
        int32_t x
        int32_t s
        int32_t fl
        uint32_t w0
        uint32_t w1
        int16_t occl
        int16_t h
        int32_t vi
        float d
    ctypedef struct HistSrc "vpp_hist_src":
        const uint8_t* L
        const uint8_t* R
        int H
        int W
        int C
        int sw_half
        int sw_len
        int sh_half
    void vpp_scan_init()
    void vpp_onehot_init()
    int vpp_scan_row_w(const float* d, int W, uint64_t* keys, int64_t* st)
    void vpp_geometry(const uint64_t* keys, int n, int32_t* xw, int32_t* fl, uint64_t* w,
                      int splat, double alpha, uint32_t wa)
    void vpp_sort_band(const BandPt* pts, const float* dv, int n, float dmin, float dmax,
                       BandPt* out, int* bucket, int* cnt)
    void vpp_occ_screen(const uint64_t* keys, const int32_t* xw, int n, const float* warp0, int WL, int lq,
                        const float* pv, int nwin, int rx2, double t, double penmax, uint8_t* out)
    void vpp_blend_span(uint8_t* dst, const uint8_t* val, int n, uint32_t w, int64_t room)
    int vpp_splat16(uint8_t* dst, const uint8_t* val, int C, int k0, int k1,
                    uint32_t w0, uint32_t w1, int64_t room)
    void vpp_splat_rows_avx2(uint8_t* dst, int64_t rs, const uint8_t* pat, int64_t p0, int64_t step,
                             int64_t mask, int nrows, int C, int k0, int k1, uint32_t w0, uint32_t w1)
    void vpp_blend_rows_avx2(uint8_t* dst, int64_t rs, const uint8_t* pat, int64_t p0, int64_t step,
                             int64_t mask, int nrows, int C, int lo, int hi, uint32_t w)
    float vpp_sw_u2f(uint32_t u)
    uint32_t vpp_w16(double w)
    int vpp_build_avx2()
    int vpp_cpu_supports_avx2()
    uint64_t vpp_hash(uint64_t seedmix, uint64_t x, uint64_t y)
    uint64_t vpp_seedmix(uint64_t seed)
    int64_t vpp_pidx(int64_t x, int64_t y)
    int vpp_ifloor(double v)
    void vpp_fgd_pixel(uint8_t* lp, const uint8_t* rp, int C, int interp, uint64_t wb, uint64_t wa)
    void* vpp_pool_take()
    int vpp_pool_give(void* s)
    int vpp_hist_pick(const uint64_t* o)
    void vpp_hist_row_tables(const HistSrc* hs, int c, int r, uint64_t* tabs)
    uint8_t vpp_hist_value(const HistSrc* hs, int c, int r, const uint64_t* tabs, int cl, int cr)

vpp_scan_init()     # constant lookup tables of the row scan and of the histogram source
vpp_onehot_init()

#: True in the build compiled for x86-64-v3 (``_sweep_avx2``), False in the portable one.
AVX2 = bool(vpp_build_avx2())
#: pattern-table entries per seed and row step of the index (tested equal to ``rng``'s)
TABLE_SIZE = VPP_TABLE_MASK + 1
ROW_STEP = VPP_ROW_STEP

cdef uint64_t LOW32 = 0xFFFFFFFFULL


def cpu_supports_avx2():
    """True when this CPU can run the x86-64-v3 build (checked before importing it)."""
    return bool(vpp_cpu_supports_avx2())


def table_padding(int C, int hmax):
    """Bytes the kernel may read past the ``TABLE_SIZE * C`` bytes of a table:
    a patch row (``2 hmax + 1`` pixels) starting at the last entry, plus SIMD over-read."""
    return (2 * hmax + 1) * C + 64


def fill_pattern_table(uint64_t seed, uint8_t[::1] out, int C):
    """Write the seed's pattern table for ``C`` channels (``rng.pattern_table``) into
    ``out[:TABLE_SIZE * C]`` and repeat its start over the rest of ``out`` (the padding)."""
    cdef int64_t core = <int64_t>TABLE_SIZE * C, n = out.shape[0], i, j, b
    cdef uint64_t sm = vpp_seedmix(seed), z
    if C < 1 or n < core:
        raise ValueError(f"out has {n} bytes, need at least {core} for {C} channel(s)")
    with nogil:
        for j in range((core + 7) // 8):
            z = vpp_hash(sm, <uint64_t>(j + 1), 0)
            for b in range(8):
                if 8 * j + b < core:
                    out[8 * j + b] = <uint8_t>(z >> (8 * b))
        for i in range(core, n):
            out[i] = out[i - core]


def hist_pick_bits(const uint64_t[::1] occupancy):
    """Histogram value of a 256-bit occupancy (4 uint64, bit v = bin v filled); -1 if all filled."""
    if occupancy.shape[0] != 4:
        raise ValueError(f"occupancy must have 4 words, got {occupancy.shape[0]}")
    return vpp_hist_pick(&occupancy[0])


cdef struct Params:
    # filled from the dict of vpp_service.vpp.params.kernel_params (one key per field)
    int pattern             # Pattern
    int uniform             # one value for the whole patch (patch > 1)
    int hmax                # patch half-size
    double alpha
    int splat
    int occlusion           # Occlusion
    int occ_window_x
    int occ_window_y
    double occ_lambda
    double occ_gamma
    double occ_t
    int mask                # PatchMask
    double adaptive_gamma
    double adaptive_dmin    # range of d of the distance-adaptive mask
    double adaptive_dmax
    double two_ss           # 2 sigma_s^2 of the bilateral mask
    double two_sc           # 2 sigma_c^2
    double neglogthr        # -ln(threshold)
    int search_width
    int search_height


cdef struct Job:
    # shared, read-only during the sweep (outputs are written row-disjointly)
    Params p
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
    int hmax            # 0 when not painting
    int splat
    int occmode
    double alpha
    uint32_t wa
    const uint8_t* pat  # padded pattern table (rng.py): a patch row is one span of it
    HistSrc hs
    int pstride         # value bytes per point in the band's value buffer (0: read from pat)
    int rstride         # bytes per patch row in it (0: one row for the whole patch)
    int ring            # power of two: rows of keys, flags and geometry kept
    int wring           # power of two >= 2 ry2 + 1: warp rows kept (a smaller ring: less cache)
    int band            # output rows painted together
    int ww              # warp columns (-W - rx2 .. W - 1 + rx2)
    int woff            # warp column index of image column 0


cdef struct Scratch:
    # per-thread buffers, grouped in blocks (capacities in bytes; cap in band points)
    void* rows_mem      # ring x W entries of keys, geo_w, geo_fl, xw, flags
    void* win_mem       # nk, wrowid, dyl, pvec, msk
    float* warp_mem     # allocation of warp (aligned to 64 bytes in it)
    void* band_mem      # bpt, spt, bd, bbucket, bcnt
    uint8_t* vbuf       # the band's pattern values (value source)
    uint64_t* tabs      # histogram window tables of one row and channel (16 W words)
    int64_t rows_cap
    int64_t win_cap
    int64_t warp_cap
    int64_t band_cap
    int64_t vcap
    int64_t tcap
    int64_t cap
    uint64_t* keys      # ring x W
    uint64_t* geo_w     # ring x W: right-view weights w0 | w1 << 32 (1/65536)
    int32_t* geo_fl     # ring x W: right-view column floor(x') (or round(x') without splat)
    int32_t* xw         # ring x W: warp column x - round(d) per key
    uint8_t* flags      # ring x W (occluded, per key)
    int* nk             # ring
    int* wrowid         # wring: the row each slot holds (-1: none)
    int* dyl            # wring: each slot's row offset from the classified row (ry2 + 1: not in the window)
    float* pvec         # nwin x wring: the current row's float penalty per (column, slot), +inf off the window
    uint8_t* msk        # K: one patch row's bilateral mask
    float* warp         # ww columns x wring slots, column-major (a column's window rows: one vector)
    BandPt* bpt         # band points in gather order (row, x)
    BandPt* spt         # in paint order (d, y, x)
    float* bd           # their d in gather order
    int* bbucket        # sort scratch: bucket ids (cap) and counts (2 cap + 1)
    int* bcnt
    int failed


cdef int _grow(void** buf, int64_t* cap, int64_t nbytes) noexcept nogil:
    """Make ``*buf`` hold ``nbytes`` (a new block when ``*cap`` is smaller; the
    contents are not kept).  Returns 1 when out of memory."""
    if nbytes <= cap[0]:
        return 0
    free(buf[0])
    buf[0] = malloc(nbytes)
    cap[0] = nbytes if buf[0] != NULL else 0
    return buf[0] == NULL


cdef int _scratch_init(const Job* J, Scratch* S) noexcept nogil:
    """Size ``S`` for ``J`` (reusing its buffers when large enough: a pooled
    Scratch comes back with the capacities of its last job) and reset its state."""
    cdef int64_t i, nk = <int64_t>J.ring * J.W + 1
    cdef int64_t nw = <int64_t>J.wring * J.ww if J.occ_on else 1
    cdef int64_t nwin = sizeof(int) * (J.ring + 2 * J.wring) + sizeof(float) * J.nwin * J.wring + 2 * J.hmax + 1
    cdef int64_t nt = 16 * <int64_t>J.W if J.paint and J.p.pattern == HISTOGRAM else 0
    S.failed = (_grow(&S.rows_mem, &S.rows_cap, nk * (2 * sizeof(uint64_t) + 2 * sizeof(int32_t) + 1))
                or _grow(&S.win_mem, &S.win_cap, nwin)
                or _grow(<void**>&S.warp_mem, &S.warp_cap, sizeof(float) * nw + 64)
                or _grow(<void**>&S.tabs, &S.tcap, sizeof(uint64_t) * nt))
    if S.failed:
        return 1
    S.keys = <uint64_t*>S.rows_mem
    S.geo_w = S.keys + nk
    S.geo_fl = <int32_t*>(S.geo_w + nk)
    S.xw = S.geo_fl + nk
    S.flags = <uint8_t*>(S.xw + nk)
    S.nk = <int*>S.win_mem
    S.wrowid = S.nk + J.ring
    S.dyl = S.wrowid + J.wring
    S.pvec = <float*>(S.dyl + J.wring)
    S.msk = <uint8_t*>(S.pvec + J.nwin * J.wring)
    S.warp = <float*>((<uintptr_t>S.warp_mem + 63) & ~(<uintptr_t>63))
    for i in range(J.ring):
        S.nk[i] = 0
    for i in range(J.wring):
        S.wrowid[i] = -1
    if J.occ_on:
        for i in range(nw):
            S.warp[i] = -INFINITY
    return 0


cdef void _scratch_free(Scratch* S) noexcept nogil:
    free(S.rows_mem)
    free(S.win_mem)
    free(S.warp_mem)
    free(S.band_mem)
    free(S.vbuf)
    free(S.tabs)


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


cdef int _reserve(const Job* J, Scratch* S, int64_t n) noexcept nogil:
    """Make the band buffers hold n points and their values; 1 when out of memory."""
    cdef int64_t cap
    if n > S.cap:
        cap = n + n // 2 + 16
        S.cap = 0
        if _grow(&S.band_mem, &S.band_cap, cap * (2 * sizeof(BandPt) + sizeof(float) + 3 * sizeof(int))
                 + sizeof(int)):
            S.failed = 1
            return 1
        S.cap = cap
        S.bpt = <BandPt*>S.band_mem
        S.spt = S.bpt + cap
        S.bd = <float*>(S.spt + cap)
        S.bbucket = <int*>(S.bd + cap)
        S.bcnt = S.bbucket + cap
    if _grow(<void**>&S.vbuf, &S.vcap, n * J.pstride + 16):     # + SIMD over-read of a span
        S.failed = 1
        return 1
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


cdef inline int _half(const Job* J, float d) noexcept nogil:
    """Patch half-size of a point of disparity d (the distance-adaptive mask shrinks it)."""
    cdef double u, lo = J.p.adaptive_dmin, hi = J.p.adaptive_dmax
    if J.p.mask != MASK_DISTANCE or hi <= lo:
        return J.hmax
    u = (<double>d - lo) / (hi - lo)
    u = 0.0 if u < 0.0 else (1.0 if u > 1.0 else u)
    return <int>floor(pow(u, J.p.adaptive_gamma) * J.hmax + 0.5)


cdef inline void _patch_cols(int x, int ph, int h, int W, int* k0, int* k1) noexcept nogil:
    """Patch pixels [k0, k1) of a point at column x with half-size ph <= h (the
    patch's largest): left position inside the image, within the half-size."""
    k0[0] = h - x if x < h else 0
    k1[0] = 2 * h + 1 if x + h < W else W - x + h
    if ph < h:
        k0[0] = max(k0[0], h - ph)
        k1[0] = min(k1[0], h + ph + 1)


cdef const uint8_t* _bilateral(const Job* J, Scratch* S, const BandPt* pt, int r, int k0, int k1) noexcept nogil:
    """The bilateral patch mask of patch row r over [k0, k1)."""
    cdef int C = J.C, k, c, dx, dy = r - pt.s, sumsq, diff
    cdef const uint8_t* cen = J.L + (<int64_t>pt.s * J.W + pt.x) * C
    cdef const uint8_t* px
    for k in range(k0, k1):
        dx = k - J.hmax
        px = J.L + (<int64_t>r * J.W + pt.x + dx) * C
        sumsq = 0
        for c in range(C):
            diff = <int>px[c] - <int>cen[c]
            sumsq = sumsq + diff * diff
        S.msk[k] = (<double>(dx * dx + dy * dy) / J.p.two_ss
                    + (<double>sumsq / <double>C) / J.p.two_sc) < J.p.neglogthr
    return S.msk


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


cdef inline void _span_mask(const Job* J, uint8_t* row, const uint8_t* vals, const uint8_t* msk,
                            int k0, int k1, int base, uint32_t w) noexcept nogil:
    """``_span`` over the runs of pixels that ``msk`` keeps (all of [k0, k1) when NULL)."""
    cdef int a
    if msk == NULL:
        _span(J, row, vals, k0, k1, base, w)
        return
    while k0 < k1:
        if not msk[k0]:
            k0 += 1
            continue
        a = k0
        while k0 < k1 and msk[k0]:
            k0 += 1
        _span(J, row, vals, a, k0, base, w)


cdef void _band_values(const Job* J, Scratch* S, int m, int b0, int b1) noexcept nogil:
    """Fill the value source of the band's gathered points ``S.bpt[:m]`` (row, x order):
    a uniform patch gets its point's value K times; the per-pixel histogram
    pattern the values of each patch row in [b0, b1).  FGD-occluded points
    paint the right view's content and get none."""
    cdef int C = J.C, h = J.hmax, K = 2 * J.hmax + 1, i, e, j, c, k, k0, k1, r, s, cn, built
    cdef const BandPt* pt
    cdef uint8_t* v
    cdef const uint8_t* src
    cdef uint8_t val
    if J.pstride == 0:
        return
    if J.p.uniform and J.p.pattern == RANDOM:
        for i in range(m):
            pt = &S.bpt[i]
            src = J.pat + vpp_pidx(pt.x, pt.s) * C
            v = S.vbuf + <int64_t>i * J.pstride
            for k in range(K):
                memcpy(v + k * C, src, C)
        return
    if J.p.uniform:                 # histogram around the point: one row of points at a time
        i = 0
        while i < m:
            s = S.bpt[i].s
            e = i
            while e < m and S.bpt[e].s == s:
                e += 1
            for c in range(C):
                built = 0
                for j in range(i, e):
                    pt = &S.bpt[j]
                    if pt.occl:
                        continue
                    if not built:
                        vpp_hist_row_tables(&J.hs, c, s, S.tabs)
                        built = 1
                    cn = <int>floor(<double>pt.x - <double>pt.d + 0.5)
                    val = vpp_hist_value(&J.hs, c, s, S.tabs, pt.x, cn)
                    v = S.vbuf + <int64_t>j * J.pstride + c
                    for k in range(K):
                        v[k * C] = val
            i = e
        return
    i = 0
    e = 0
    for r in range(b0, b1):         # histogram per patch pixel: one band row at a time
        while i < m and S.bpt[i].s < r - h:     # [i, e): the points of rows r - h .. r + h
            i += 1
        while e < m and S.bpt[e].s <= r + h:
            e += 1
        for c in range(C):
            built = 0
            for j in range(i, e):
                pt = &S.bpt[j]
                if pt.occl or r - pt.s > pt.h or pt.s - r > pt.h:
                    continue
                if not built:
                    vpp_hist_row_tables(&J.hs, c, r, S.tabs)
                    built = 1
                _patch_cols(pt.x, pt.h, h, J.W, &k0, &k1)
                cn = <int>floor(<double>pt.x - <double>pt.d + 0.5) - h
                v = S.vbuf + <int64_t>j * J.pstride + (r - pt.s + h) * J.rstride + c
                for k in range(k0, k1):
                    v[k * C] = vpp_hist_value(&J.hs, c, r, S.tabs, pt.x + k - h, cn + k)


cdef void _paint_band(const Job* J, Scratch* S, int b0, int b1) noexcept nogil:
    """Paint output rows [b0, b1): every point of rows b0-h .. b1-1+h, in the global
    order (d, y, x), blended into the band rows it covers (right view, then left)."""
    cdef int H = J.H, W = J.W, C = J.C, h = J.hmax, K = 2 * J.hmax + 1
    cdef int64_t rs = <int64_t>W * C
    cdef int s0 = b0 - h if b0 - h > 0 else 0
    cdef int s1 = b1 - 1 + h if b1 - 1 + h < H - 1 else H - 1
    cdef int occmode = J.occmode
    cdef int use_flags = occmode == OCC_NO or occmode == OCC_FGD
    cdef int bil = J.p.mask == MASK_BILATERAL, distance = J.p.mask == MASK_DISTANCE
    cdef int splat = J.splat, pstride = J.pstride, rstride = J.rstride
    cdef uint32_t wa = J.wa
    cdef const uint8_t* pat = J.pat
    cdef const uint8_t* vpt         # a point's values in the band's value buffer (value source)
    # a patch column in one go (AVX2 build, values read from the table, no bilateral
    # mask, C in {1, 3}, the patch plus a splat column within 16 bytes)
    cdef int rows_fast = (vpp_build_avx2() and J.pstride == 0 and not bil
                          and (C == 1 or C == 3) and (K + 1) * C <= 16)
    cdef int s, slot, i, j, m, x, r, r0, r1, k0, k1, k, c, fl, flag, base, ph
    cdef BandPt* pt
    cdef int64_t total = 0
    cdef uint64_t key, wpair
    cdef const uint8_t* v
    cdef const uint8_t* mk
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
    # 1. gather the points in (row, x) order (NO-occluded points are dropped), fill
    #    the value source and sort them stably by d: the global order (d, y, x)
    m = 0
    dmin = INFINITY
    dmax = -INFINITY
    for s in range(s0, s1 + 1):
        slot = s & (J.ring - 1)
        base = slot * W
        for i in range(S.nk[slot]):
            flag = S.flags[base + i] if use_flags else 0
            if flag and occmode == OCC_NO:
                continue
            key = S.keys[base + i]
            d = vpp_sw_u2f(<uint32_t>(key >> 32))
            pt = &S.bpt[m]
            pt.x = <int32_t>(key & LOW32)
            pt.s = s
            pt.fl = S.geo_fl[base + i]
            wpair = S.geo_w[base + i]
            pt.w0 = <uint32_t>(wpair & LOW32)
            pt.w1 = <uint32_t>(wpair >> 32)
            pt.occl = flag
            pt.h = _half(J, d) if distance else h
            pt.vi = m
            pt.d = d
            S.bd[m] = d
            dmin = d if d < dmin else dmin
            dmax = d if d > dmax else dmax
            m += 1
    _band_values(J, S, m, b0, b1)
    vpp_sort_band(S.bpt, S.bd, m, dmin, dmax, S.spt, S.bbucket, S.bcnt)
    # 2. right view: each visible point's values per covered band row, splatted
    for j in range(m):
        pt = &S.spt[j]
        if pt.occl:
            continue
        s = pt.s
        x = pt.x
        ph = pt.h
        _patch_cols(x, ph, h, W, &k0, &k1)
        fl = pt.fl
        w0 = pt.w0
        w1 = pt.w1
        r0 = max(s - ph, b0)
        r1 = min(s + ph, b1 - 1)
        if rows_fast and fl - h >= 0 and fl + h + 1 < W and <int64_t>(W - fl + h) * C >= 16:
            if splat:
                vpp_splat_rows_avx2(J.oR + r0 * rs + (fl - h) * C, rs, pat, x - h + <int64_t>r0 * VPP_ROW_STEP,
                                    VPP_ROW_STEP, VPP_TABLE_MASK, r1 - r0 + 1, C, k0, k1, w0, w1)
            else:
                vpp_blend_rows_avx2(J.oR + r0 * rs + (fl - h) * C, rs, pat, x - h + <int64_t>r0 * VPP_ROW_STEP,
                                    VPP_ROW_STEP, VPP_TABLE_MASK, r1 - r0 + 1, C, k0 * C, k1 * C, w0)
            continue
        vpt = S.vbuf + <int64_t>pt.vi * pstride + (h - s) * rstride
        for r in range(r0, r1 + 1):
            v = pat + vpp_pidx(x - h, r) * C if pstride == 0 else vpt + r * rstride
            mk = _bilateral(J, S, pt, r, k0, k1) if bil else NULL
            oR = J.oR + r * rs
            if splat:
                if (mk != NULL or fl - h < 0 or fl + h + 1 >= W or not vpp_splat16(
                        oR + (fl - h) * C, v, C, k0, k1, w0, w1, <int64_t>(W - fl + h) * C)):
                    if w1:
                        _span_mask(J, oR, v, mk, k0, k1, fl - h + 1, w1)
                    _span_mask(J, oR, v, mk, k0, k1, fl - h, w0)
            else:
                _span_mask(J, oR, v, mk, k0, k1, fl - h, w0)
    # 3. left view: the values, or (FGD) the final right row's content at x'
    for j in range(m):
        pt = &S.spt[j]
        s = pt.s
        x = pt.x
        ph = pt.h
        _patch_cols(x, ph, h, W, &k0, &k1)
        r0 = max(s - ph, b0)
        r1 = min(s + ph, b1 - 1)
        if not pt.occl:
            if rows_fast and x - h >= 0 and <int64_t>(W - x + h) * C >= 16:
                vpp_blend_rows_avx2(J.oL + r0 * rs + (x - h) * C, rs, pat, x - h + <int64_t>r0 * VPP_ROW_STEP,
                                    VPP_ROW_STEP, VPP_TABLE_MASK, r1 - r0 + 1, C, k0 * C, k1 * C, wa)
                continue
            vpt = S.vbuf + <int64_t>pt.vi * pstride + (h - s) * rstride
            for r in range(r0, r1 + 1):
                v = pat + vpp_pidx(x - h, r) * C if pstride == 0 else vpt + r * rstride
                _span_mask(J, J.oL + r * rs, v, _bilateral(J, S, pt, r, k0, k1) if bil else NULL, k0, k1, x - h, wa)
            continue
        xp = <double>x - <double>pt.d
        if splat:
            fl = vpp_ifloor(xp)
            beta = xp - <double>fl
        else:
            fl = vpp_ifloor(xp + 0.5)
            beta = 0.0
        wb = vpp_w16(beta)
        for r in range(r0, r1 + 1):
            oL = J.oL + r * rs
            oR = J.oR + r * rs
            mk = _bilateral(J, S, pt, r, k0, k1) if bil else NULL
            for k in range(k0, k1):
                c = fl + k - h
                if (mk != NULL and not mk[k]) or c < 0 or c >= W or (beta > 0 and c + 1 >= W):
                    continue
                vpp_fgd_pixel(oL + (x + k - h) * C, oR + c * C, C, beta > 0, wb, wa)


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


cdef tuple _prepare(Job* J, const float[:, ::1] disp, uint8_t[:, ::1] occ, dict params, bint paint):
    """Fill the fields of ``J`` shared by both entry points; returns the arrays it
    points into: (row stats H x 4, occluded count per row, penalties)."""
    cdef int H = disp.shape[0], W = disp.shape[1], need
    memset(J, 0, sizeof(Job))
    J.p = params
    if occ.shape[0] != H or occ.shape[1] != W:
        raise ValueError(f"occ has shape {(occ.shape[0], occ.shape[1])}, the disparity {(H, W)}")
    if H == 0 or W == 0:
        raise ValueError(f"empty disparity map {(H, W)}")
    J.disp = &disp[0, 0]
    J.H = H
    J.W = W
    J.occ_on = J.p.occlusion != OCC_OFF or not paint
    J.rx2 = J.p.occ_window_x // 2
    J.ry2 = J.p.occ_window_y // 2
    J.nwin = 2 * J.rx2 + 1
    # lam * (gamma * |dx| + (1 - gamma) * |dy|), in NumPy's float64 (the reference's rounding)
    adx = np.abs(np.arange(-J.rx2, J.rx2 + 1, dtype=np.float64))[None, :]
    ady = np.abs(np.arange(-J.ry2, J.ry2 + 1, dtype=np.float64))[:, None]
    pen = np.ascontiguousarray(J.p.occ_lambda * (J.p.occ_gamma * adx + (1.0 - J.p.occ_gamma) * ady))
    J.penmax = float(pen.max())
    pen[J.ry2, J.rx2] = np.inf
    cdef const double[:, ::1] pv = pen
    J.pen = &pv[0, 0]
    J.t = J.p.occ_t
    J.occ = &occ[0, 0]
    stats = np.zeros((H, 4), np.int64)
    cnt = np.zeros(H, np.int64)
    cdef int64_t[:, ::1] st = stats
    cdef int64_t[::1] cn = cnt
    J.stats = &st[0, 0]
    J.occ_cnt = &cn[0]
    J.paint = paint
    J.hmax = J.p.hmax if paint else 0
    J.splat = J.p.splat
    J.occmode = J.p.occlusion
    J.alpha = J.p.alpha
    J.wa = vpp_w16(J.p.alpha)
    J.band = 16 if paint else 1
    # rows alive at once: a band and its patch margins, plus the occlusion window lag
    need = J.band + 2 * J.hmax
    if J.occ_on:
        need = max(need + J.ry2, 2 * J.ry2 + 1)
    J.ring = 1
    while J.ring < need:
        J.ring *= 2
    J.wring = 1                      # <= ring (need >= 2 ry2 + 1 when occ_on)
    while J.wring < 2 * J.ry2 + 1:
        J.wring *= 2
    J.ww = 2 * W + 2 * J.rx2         # warp columns -W - rx2 .. W - 1 + rx2
    J.woff = W + J.rx2
    return stats, cnt, pen


cdef void _run(const Job* J, int nthreads) except *:
    """The sweep over chunks of rows, one Scratch per thread."""
    cdef int ci, nchunks = 1 if nthreads <= 1 else min(J.H, 4 * nthreads)
    cdef int chunk = (J.H + nchunks - 1) // nchunks
    cdef int failed[1]
    cdef Scratch* S = NULL
    failed[0] = 0
    nchunks = (J.H + chunk - 1) // chunk
    with nogil, parallel(num_threads=nthreads):
        S = _scratch_take()
        if S != NULL:
            _scratch_init(J, S)
        for ci in prange(nchunks, schedule="dynamic"):
            if S == NULL or S.failed:
                failed[0] = 1
            else:
                _run_chunk(J, S, ci * chunk, min(J.H, ci * chunk + chunk))
        if S != NULL:
            if S.failed:
                failed[0] = 1
            _scratch_give(S)
    if failed[0]:
        raise MemoryError("VPP sweep: out of memory for the per-thread buffers")


def paint(const float[:, ::1] disp, uint8_t[:, ::1] occ,
          const uint8_t[:, :, ::1] left, const uint8_t[:, :, ::1] right,
          uint8_t[:, :, ::1] out_left, uint8_t[:, :, ::1] out_right,
          dict params, const uint8_t[::1] pattern, int nthreads):
    """Paint the variant of ``params`` (:func:`~vpp_service.vpp.params.kernel_params`)
    into ``out_left`` / ``out_right`` and fill ``occ`` (H x W, 1 at occluded points).

    ``pattern`` is the seed's table padded by ``table_padding(C, hmax)`` bytes
    (:func:`fill_pattern_table`), None for the histogram pattern.  Returns
    ``(row stats H x 4: given, valid, invalid, left-border; occluded count per row)``.
    """
    cdef Job J
    keep = _prepare(&J, disp, occ, params, True)
    cdef int C = left.shape[2], K = 2 * J.hmax + 1
    shapes = [tuple(a.shape[:3]) for a in (left.base, right.base, out_left.base, out_right.base)]
    if any(sh != (J.H, J.W, C) for sh in shapes):
        raise ValueError(f"image shapes (left, right, out_left, out_right) {shapes} differ from {(J.H, J.W, C)}")
    J.L = &left[0, 0, 0]
    J.R = &right[0, 0, 0]
    J.oL = &out_left[0, 0, 0]
    J.oR = &out_right[0, 0, 0]
    J.C = C
    if J.p.pattern == RANDOM:
        need = TABLE_SIZE * C + table_padding(C, J.hmax)
        if pattern is None or pattern.shape[0] < need:
            raise ValueError(f"pattern table has {0 if pattern is None else pattern.shape[0]} bytes, need {need}")
        J.pat = &pattern[0]
    J.hs.L = J.L
    J.hs.R = J.R
    J.hs.H = J.H
    J.hs.W = J.W
    J.hs.C = C
    J.hs.sw_half = J.p.search_width // 2
    J.hs.sw_len = J.p.search_width
    J.hs.sh_half = J.p.search_height // 2
    if J.p.pattern == HISTOGRAM and not J.p.uniform:
        J.rstride = K * C
        J.pstride = K * J.rstride
    elif J.p.uniform:
        J.pstride = K * C
    _run(&J, nthreads)
    return keep[0], keep[1]


def occlusions(const float[:, ::1] disp, uint8_t[:, ::1] occ, dict params, int nthreads):
    """Classify the points of ``disp`` (the occlusion fields of ``params``) into
    ``occ`` without painting.  Returns ``(row stats H x 4, occluded count per row)``."""
    cdef Job J
    keep = _prepare(&J, disp, occ, params, False)
    _run(&J, nthreads)
    return keep[0], keep[1]
