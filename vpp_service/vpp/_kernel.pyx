# distutils: language = c++
"""General Cython kernel of Virtual Pattern Projection (called by :mod:`vpp_service.vpp.project`).

Paints every variant that the fused sweep kernel (``_sweep.pyx``) does not:
the histogram pattern, patch-uniform values and the adaptive patches.  The
occlusion mask comes from ``_sweep`` (classify-only run).

Pipeline (every phase is a ``prange`` over image rows, so it is parallel and
race-free; results do not depend on the thread count):

A. count the points of each row (given / valid / invalid / left-border);
B. (serial, tiny) prefix sums give each row a slice of the key array;
C. fill each row's keys ``(float_bits(d) << 32) | x`` and sort them with
   ``std::sort`` (positive float bits are monotone, so the row is in (d, x) order);
E. (histogram + uniform patch only) one value per point and channel;
F. paint: row r of both outputs is owned by one thread; it copies the input
   rows, k-way merges the sorted keys of source rows r-h..r+h into the global
   order (d, y, x), computes the pattern values of that row once, blends them
   into the right row (splatting), then into the left row (FGD reads the final
   right row r).

Histogram speed: only the occupancy of the 256 bins matters unless all are
filled.  For a (centre row, channel) we build, per aligned 32-column block,
prefix-OR and suffix-OR tables of 256-bit occupancy (4 uint64) over the
``search_height`` rows; any window of length L is then ``suffix[a] | full
middle blocks | prefix[e]`` (3 lookups for L=64).  The tables are built in C
(``vpp_build_tables``): the 256-bit one-hot of a byte comes from an 8 KiB table
(``vpp_onehot``) and the words are ORed as two 128-bit vectors (GCC/Clang vector
extensions; SSE2 on plain x86-64), or as one 256-bit register on CPUs with AVX2
(a copy compiled for AVX2 by a target attribute, chosen at import:
:func:`tables_use_avx2`, set by :mod:`~vpp_service.vpp.backend`; same bytes).  The gap search is bit-parallel
(``vpp_hist_pick``).  If every bin is filled the window is counted exactly (rare).
"""
from cython.parallel cimport prange, parallel
cimport openmp
from libc.stdint cimport uint8_t, uint32_t, uint64_t, int64_t, int32_t, int8_t
from libc.stdlib cimport malloc, free
from libc.string cimport memcpy, memset
from libc.math cimport floor, pow

from vpp_service.vpp._pixel cimport _pidx, _w16, _blend16, _fgd_pixel

import numpy as np

vpp_init_onehot()


def tables_use_avx2(bint on):
    """Build the histogram window tables with AVX2 (when this CPU and build can)
    or with the portable code; same bytes.  Returns whether AVX2 is now used.
    :mod:`vpp_service.vpp.backend` sets it at import, with the sweep build it
    chooses (``backend.AVX2``); tests switch it to check both.  Not to be
    called while a kernel runs."""
    return bool(vpp_tables_use_avx2(on))

cdef extern from *:
    """
    #include <stdint.h>
    #include <string.h>
    static inline int vpp_ctz64(uint64_t v) { return __builtin_ctzll(v); }
    static inline uint32_t vpp_f2u(float f) { uint32_t u; memcpy(&u, &f, 4); return u; }
    static inline float vpp_u2f(uint32_t u) { float f; memcpy(&f, &u, 4); return f; }
    /* 256-bit words: bit p is word p >> 6, bit p & 63. r = a >> s (r[p] = a[p + s]). */
    static inline void vpp_shr256(const uint64_t* a, int s, uint64_t* r) {
        int q = s >> 6, b = s & 63, i;
        if (q == 0) {           /* common case, 0 < s < 64 */
            r[0] = (a[0] >> b) | (a[1] << (64 - b));
            r[1] = (a[1] >> b) | (a[2] << (64 - b));
            r[2] = (a[2] >> b) | (a[3] << (64 - b));
            r[3] = a[3] >> b;
            return;
        }
        for (i = 0; i < 4; i++) {
            uint64_t lo = (i + q < 4) ? a[i + q] : 0;
            uint64_t hi = (i + q + 1 < 4) ? a[i + q + 1] : 0;
            r[i] = b ? ((lo >> b) | (hi << (64 - b))) : lo;
        }
    }
    static inline int vpp_ctz256(const uint64_t* a) {
        int i;
        for (i = 0; i < 4; i++) if (a[i]) return (i << 6) + __builtin_ctzll(a[i]);
        return 256;
    }
    static inline int vpp_top256(const uint64_t* a) {   /* highest set bit, -1 if none */
        int i;
        for (i = 3; i >= 0; i--) if (a[i]) return (i << 6) + 63 - __builtin_clzll(a[i]);
        return -1;
    }
    static inline int vpp_nz256(const uint64_t* a) { return (a[0] | a[1] | a[2] | a[3]) != 0; }
    /* Value farthest from every filled bin of the 256-bit occupancy o (ties: smallest);
       -1 if all filled.  Bit-parallel: P[j] marks the starts of >= 2^j zero runs
       (interior runs only), binary lifting gives the longest run and the first run
       reaching the best half-length. */
    static int vpp_hist_pick(const uint64_t* o) {
        uint64_t Z[4], P[9][4], cur[4], t[4];
        int f1, ls, lead, trail, i, j, top, k, m, kp, rem, p0, best_i, best_d;
        if ((o[0] & o[1] & o[2] & o[3]) == 0xFFFFFFFFFFFFFFFFULL) return -1;
        if (!vpp_nz256(o)) return 0;
        f1 = vpp_ctz256(o);
        ls = vpp_top256(o);
        lead = f1;
        trail = 255 - ls;
        best_i = 0;
        best_d = lead;
        for (i = 0; i < 4; i++) {
            int lo = i << 6;
            uint64_t w = ~o[i];
            /* keep positions f1 < p < ls */
            if (f1 + 1 > lo) w &= (f1 + 1 - lo >= 64) ? 0 : (~0ULL << (f1 + 1 - lo));
            if (ls < lo + 64) w &= (ls - lo <= 0) ? 0 : (~0ULL >> (64 - (ls - lo)));
            Z[i] = w;
        }
        if (vpp_nz256(Z)) {
            for (i = 0; i < 4; i++) P[0][i] = Z[i];
            top = 0;
            while (top < 8) {
                vpp_shr256(P[top], 1 << top, t);
                for (i = 0; i < 4; i++) t[i] &= P[top][i];
                if (!vpp_nz256(t)) break;
                top++;
                for (i = 0; i < 4; i++) P[top][i] = t[i];
            }
            for (i = 0; i < 4; i++) cur[i] = P[top][i];
            k = 1 << top;
            for (j = top - 1; j >= 0; j--) {
                vpp_shr256(P[j], k, t);
                for (i = 0; i < 4; i++) t[i] &= cur[i];
                if (vpp_nz256(t)) {
                    for (i = 0; i < 4; i++) cur[i] = t[i];
                    k += 1 << j;
                }
            }
            m = (k + 1) >> 1;
            if (m > best_d) {
                kp = 2 * m - 1;        /* shortest run whose half is m */
                for (i = 0; i < 4; i++) cur[i] = Z[i];
                k = 1;
                rem = kp - 1;
                for (j = 0; rem; j++, rem >>= 1) {
                    if (rem & 1) {
                        vpp_shr256(P[j], k, t);
                        for (i = 0; i < 4; i++) cur[i] &= t[i];
                        k += 1 << j;
                    }
                }
                p0 = vpp_ctz256(cur);
                best_d = m;
                best_i = p0 - 1 + m;
            }
        }
        if (trail > best_d) best_i = 255;
        return best_i;
    }
    /* ---- histogram tables: a 256-bit occupancy word is two 128-bit GCC/Clang vectors
       (one SSE2 register each on x86-64); one-hot of each byte value from an 8 KiB table. */
    typedef uint64_t vpp_v2 __attribute__((vector_size(16)));
    static vpp_v2 vpp_onehot[256][2];
    static void vpp_init_onehot(void) {
        int v, i;
        for (v = 0; v < 256; v++) {
            for (i = 0; i < 4; i++) vpp_onehot[v][i >> 1][i & 1] = 0;
            vpp_onehot[v][v >> 7][(v >> 6) & 1] = (uint64_t)1 << (v & 63);
        }
    }
    /* unaligned load / store of a 128-bit half */
    static inline vpp_v2 vpp_ld2(const uint64_t* p) { vpp_v2 v; memcpy(&v, p, 16); return v; }
    static inline void vpp_st2(uint64_t* p, vpp_v2 v) { memcpy(p, &v, 16); }
    /* Per aligned 32-column block, prefix/suffix OR of the bin occupancy of the
       columns over rows r +- sh_half (clipped) of channel c. */
    static void vpp_build_tables_portable(const uint8_t* img, int H, int W, int C, int c, int r,
                                 int sh_half, uint64_t* pre, uint64_t* suf) {
        int y0 = r - sh_half, y1 = r + sh_half, b0, b1, x, y;
        const int64_t rs = (int64_t)W * C;
        const vpp_v2 zero = {0, 0};
        if (y0 < 0) y0 = 0;
        if (y1 > H - 1) y1 = H - 1;
        for (b0 = 0; b0 < W; b0 += 32) {
            vpp_v2 acc0 = zero, acc1 = zero;
            b1 = b0 + 32 < W ? b0 + 32 : W;
            for (x = b0; x < b1; x++) {
                const uint8_t* p = img + ((int64_t)y0 * W + x) * C + c;
                vpp_v2 a0 = vpp_onehot[p[0]][0], a1 = vpp_onehot[p[0]][1];
                for (y = y0 + 1; y <= y1; y++) {
                    p += rs;
                    a0 |= vpp_onehot[p[0]][0];
                    a1 |= vpp_onehot[p[0]][1];
                }
                vpp_st2(suf + 4 * (int64_t)x, a0);
                vpp_st2(suf + 4 * (int64_t)x + 2, a1);
                acc0 |= a0;
                acc1 |= a1;
                vpp_st2(pre + 4 * (int64_t)x, acc0);
                vpp_st2(pre + 4 * (int64_t)x + 2, acc1);
            }
            acc0 = zero;
            acc1 = zero;
            for (x = b1 - 1; x >= b0; x--) {
                acc0 |= vpp_ld2(suf + 4 * (int64_t)x);
                acc1 |= vpp_ld2(suf + 4 * (int64_t)x + 2);
                vpp_st2(suf + 4 * (int64_t)x, acc0);
                vpp_st2(suf + 4 * (int64_t)x + 2, acc1);
            }
        }
    }
    #include "_sweep.h"      /* vpp_cpu_supports_avx2 (include-guarded) */
    #if defined(__GNUC__) && defined(__x86_64__)
    #include <immintrin.h>
    /* vpp_build_tables on 256-bit registers (a whole occupancy per load, OR and
       store), compiled for AVX2 by a target attribute and chosen at run time. */
    __attribute__((target("avx2")))
    static void vpp_build_tables_avx2(const uint8_t* img, int H, int W, int C, int c, int r,
                                      int sh_half, uint64_t* pre, uint64_t* suf) {
        int y0 = r - sh_half, y1 = r + sh_half, b0, b1, x, y;
        const int64_t rs = (int64_t)W * C;
        if (y0 < 0) y0 = 0;
        if (y1 > H - 1) y1 = H - 1;
        for (b0 = 0; b0 < W; b0 += 32) {
            __m256i acc = _mm256_setzero_si256();
            b1 = b0 + 32 < W ? b0 + 32 : W;
            for (x = b0; x < b1; x++) {
                const uint8_t* p = img + ((int64_t)y0 * W + x) * C + c;
                __m256i a = _mm256_loadu_si256((const __m256i*)vpp_onehot[p[0]]);
                for (y = y0 + 1; y <= y1; y++) {
                    p += rs;
                    a = _mm256_or_si256(a, _mm256_loadu_si256((const __m256i*)vpp_onehot[p[0]]));
                }
                _mm256_storeu_si256((__m256i*)(suf + 4 * (int64_t)x), a);
                acc = _mm256_or_si256(acc, a);
                _mm256_storeu_si256((__m256i*)(pre + 4 * (int64_t)x), acc);
            }
            acc = _mm256_setzero_si256();
            for (x = b1 - 1; x >= b0; x--) {
                acc = _mm256_or_si256(acc, _mm256_loadu_si256((const __m256i*)(suf + 4 * (int64_t)x)));
                _mm256_storeu_si256((__m256i*)(suf + 4 * (int64_t)x), acc);
            }
        }
    }
    #define VPP_TABLES_AVX2 1
    #else
    #define VPP_TABLES_AVX2 0
    #endif
    static int vpp_tables_avx2 = 0;   /* set at import (vpp_tables_use_avx2), before any kernel runs */
    /* choose the AVX2 builder (if built and the CPU can run the AVX2 sweep build:
       the same test) or the portable one; returns the choice */
    static int vpp_tables_use_avx2(int on) {
        vpp_tables_avx2 = VPP_TABLES_AVX2 && on && vpp_cpu_supports_avx2();
        return vpp_tables_avx2;
    }
    static void vpp_build_tables(const uint8_t* img, int H, int W, int C, int c, int r,
                                 int sh_half, uint64_t* pre, uint64_t* suf) {
    #if VPP_TABLES_AVX2
        if (vpp_tables_avx2) {
            vpp_build_tables_avx2(img, H, W, C, c, r, sh_half, pre, suf);
            return;
        }
    #endif
        vpp_build_tables_portable(img, H, W, C, c, r, sh_half, pre, suf);
    }
    """
    int vpp_ctz64(uint64_t v) nogil
    uint32_t vpp_f2u(float f) nogil
    float vpp_u2f(uint32_t u) nogil
    int vpp_hist_pick(const uint64_t* o) nogil
    void vpp_init_onehot() nogil
    int vpp_tables_use_avx2(int on) nogil
    void vpp_build_tables(const uint8_t* img, int H, int W, int C, int c, int r,
                          int sh_half, uint64_t* pre, uint64_t* suf) nogil

cdef extern from "_sweep.h" nogil:
    int vpp_scan_row(const float* d, int W, uint64_t* keys, int64_t* st)
    void vpp_sort_keys(uint64_t* keys, int n, uint64_t* tmp, int* bucket, int* cnt)


cdef uint64_t ALL1 = 0xFFFFFFFFFFFFFFFFULL
cdef uint64_t LOW32 = 0xFFFFFFFFULL


cdef struct Ctx:
    const uint8_t* L
    const uint8_t* R
    uint8_t* oL
    uint8_t* oR
    const uint8_t* occ
    const uint64_t* pkey
    const int64_t* off
    const int8_t* hp
    const uint8_t* uvals
    int H
    int W
    int C
    int hmax
    int pattern
    int uniform
    int splat
    int occmode
    int bilateral
    double two_ss
    double two_sc
    double neglogthr
    double alpha
    uint64_t wa
    const uint8_t* pat  # padded pattern table (rng.py)
    int sw_half
    int sw_len
    int sh_half


cdef inline void _or4(uint64_t* o, const uint64_t* t) noexcept nogil:
    o[0] |= t[0]
    o[1] |= t[1]
    o[2] |= t[2]
    o[3] |= t[3]


cdef inline void _window_rows(const Ctx* cx, int r, int* y0, int* y1) noexcept nogil:
    """Rows ``[y0, y1]`` of the histogram search window centred on row r, clipped to the image."""
    y0[0] = r - cx.sh_half if r - cx.sh_half > 0 else 0
    y1[0] = r + cx.sh_half if r + cx.sh_half < cx.H - 1 else cx.H - 1


cdef inline void _window_or(const Ctx* cx, const uint8_t* img, int c, int r,
                     const uint64_t* pre, const uint64_t* suf, int cen, uint64_t* o) noexcept nogil:
    """OR the occupancy of columns [cen - L//2, cen - L//2 + L - 1] (clipped) into o."""
    cdef int W = cx.W
    cdef int a = cen - cx.sw_half
    cdef int e = a + cx.sw_len - 1
    cdef int ba, be, b, x, y, y0, y1, bend
    cdef unsigned v
    if a < 0:
        a = 0
    if e > W - 1:
        e = W - 1
    if a > e:
        return
    ba = a >> 5
    be = e >> 5
    if ba < be:
        _or4(o, suf + 4 * a)
        for b in range(ba + 1, be):
            _or4(o, suf + 4 * (b << 5))
        _or4(o, pre + 4 * e)
        return
    bend = (ba << 5) + 31
    if bend > W - 1:
        bend = W - 1
    if a == (ba << 5):
        _or4(o, pre + 4 * e)
    elif e == bend:
        _or4(o, suf + 4 * a)
    else:
        _window_rows(cx, r, &y0, &y1)
        for y in range(y0, y1 + 1):
            for x in range(a, e + 1):
                v = img[(<int64_t>y * W + x) * cx.C + c]
                o[v >> 6] |= (<uint64_t>1) << (v & 63)


cdef void _window_count(const Ctx* cx, const uint8_t* img, int c, int r, int cen,
                        int32_t* counts) noexcept nogil:
    cdef int W = cx.W
    cdef int a = cen - cx.sw_half
    cdef int e = a + cx.sw_len - 1
    cdef int x, y, y0, y1
    if a < 0:
        a = 0
    if e > W - 1:
        e = W - 1
    _window_rows(cx, r, &y0, &y1)
    for y in range(y0, y1 + 1):
        for x in range(a, e + 1):
            counts[img[(<int64_t>y * W + x) * cx.C + c]] += 1


cdef inline uint8_t _hist_value(const Ctx* cx, int c, int r, const uint64_t* tabs, int cl, int cr) noexcept nogil:
    """Histogram pattern value of channel c for windows centred on (cl, r) in L and (cr, r) in R.

    ``tabs`` holds the tables of centre row r, channel c: preL, sufL, preR, sufR
    (each 4*W words).
    """
    cdef uint64_t o[4]
    cdef int32_t counts[256]
    cdef int v, i, best
    cdef int W4 = 4 * cx.W
    o[0] = 0
    o[1] = 0
    o[2] = 0
    o[3] = 0
    _window_or(cx, cx.L, c, r, tabs, tabs + W4, cl, o)
    _window_or(cx, cx.R, c, r, tabs + 2 * W4, tabs + 3 * W4, cr, o)
    v = vpp_hist_pick(o)
    if v >= 0:
        return <uint8_t>v
    memset(counts, 0, sizeof(counts))
    _window_count(cx, cx.L, c, r, cl, counts)
    _window_count(cx, cx.R, c, r, cr, counts)
    best = 0
    for i in range(1, 256):
        if counts[i] < counts[best]:
            best = i
    return <uint8_t>best


cdef inline void _build_all(const Ctx* cx, int c, int r, uint64_t* tabs) noexcept nogil:
    cdef int W4 = 4 * cx.W
    vpp_build_tables(cx.L, cx.H, cx.W, cx.C, c, r, cx.sh_half, tabs, tabs + W4)
    vpp_build_tables(cx.R, cx.H, cx.W, cx.C, c, r, cx.sh_half, tabs + 2 * W4, tabs + 3 * W4)


# ----------------------------------------------------------------- phases
cdef void _uniform_hist_row(const Ctx* cx, int s, uint64_t* tabs, uint8_t* uvals) noexcept nogil:
    """Histogram value of every point of row s (uniform patches), all channels."""
    cdef int64_t b = cx.off[s], e = cx.off[s + 1], i
    cdef int c, x, cr
    cdef double d
    if b == e:
        return
    for c in range(cx.C):
        _build_all(cx, c, s, tabs)
        for i in range(b, e):
            x = <int>(cx.pkey[i] & LOW32)
            d = vpp_u2f(<uint32_t>(cx.pkey[i] >> 32))
            cr = <int>floor(<double>x - d + 0.5)
            uvals[i * cx.C + c] = _hist_value(cx, c, s, tabs, x, cr)


cdef void _paint_row(const Ctx* cx, int r, int64_t* heads, int64_t* ends, int64_t* cidx,
                     int32_t* crow, uint8_t* vbuf, uint8_t* mbuf, uint64_t* tabs) noexcept nogil:
    cdef int H = cx.H, W = cx.W, C = cx.C, hmax = cx.hmax
    cdef int K = 2 * hmax + 1
    cdef int64_t rowb = <int64_t>r * W * C
    cdef int s_lo, s_hi, nsrc, j, jbest, s, h, x, dx, dy, c, col, fl, cn, k, ncon, n, xl
    cdef int64_t idx
    cdef uint64_t key, kbest, w0, w1, wb, v16, src, i0, i1
    cdef double d, xp, beta, e
    cdef int sumsq, diff, occ_pt
    cdef uint8_t* oL = cx.oL + rowb
    cdef uint8_t* oR = cx.oR + rowb
    cdef const uint8_t* Lr = cx.L + rowb
    cdef uint8_t* vals
    cdef uint8_t* msk
    cdef const uint64_t* pkey = cx.pkey
    cdef const int8_t* hp = cx.hp
    cdef int occmode = cx.occmode
    cdef int pattern = cx.pattern
    cdef int uniform = cx.uniform
    cdef int bilateral = cx.bilateral
    cdef int splat = cx.splat
    cdef uint64_t wa = cx.wa
    cdef const uint8_t* pv
    cdef double alpha = cx.alpha
    memcpy(oL, Lr, W * C)
    memcpy(oR, cx.R + rowb, W * C)
    s_lo = r - hmax
    if s_lo < 0:
        s_lo = 0
    s_hi = r + hmax
    if s_hi > H - 1:
        s_hi = H - 1
    nsrc = s_hi - s_lo + 1
    for j in range(nsrc):
        heads[j] = cx.off[s_lo + j]
        ends[j] = cx.off[s_lo + j + 1]
    # 1. merge the source rows in global (d, y, x) order
    ncon = 0
    while True:
        jbest = -1
        kbest = 0
        for j in range(nsrc):
            if heads[j] < ends[j]:
                key = pkey[heads[j]] >> 32      # d bits only: ties -> smaller row
                if jbest < 0 or key < kbest:
                    jbest = j
                    kbest = key
        if jbest < 0:
            break
        idx = heads[jbest]
        heads[jbest] += 1
        kbest = pkey[idx]
        s = s_lo + jbest
        dy = r - s
        if dy < 0:
            dy = -dy
        h = hmax if hp == NULL else hp[idx]
        if dy > h:
            continue
        x = <int>(kbest & LOW32)
        occ_pt = 0
        if cx.occ != NULL and occmode != 2:
            occ_pt = cx.occ[<int64_t>s * W + x]
        if occ_pt and occmode == 1:
            continue
        cidx[ncon] = idx
        crow[ncon] = s if not occ_pt else -1 - s
        ncon += 1
    if ncon == 0:
        return
    # 2. masks (inside image, bilateral) and pattern values, per contribution
    for n in range(ncon):
        idx = cidx[n]
        s = crow[n] if crow[n] >= 0 else -1 - crow[n]
        x = <int>(pkey[idx] & LOW32)
        h = hmax if hp == NULL else hp[idx]
        msk = mbuf + <int64_t>n * K
        for k in range(K):
            dx = k - hmax
            xl = x + dx
            if dx < -h or dx > h or xl < 0 or xl >= W:
                msk[k] = 0
                continue
            msk[k] = 1
            if bilateral:
                sumsq = 0
                for c in range(C):
                    diff = <int>Lr[xl * C + c] - <int>cx.L[(<int64_t>s * W + x) * C + c]
                    sumsq = sumsq + diff * diff
                e = <double>(dx * dx + (r - s) * (r - s)) / cx.two_ss + \
                    (<double>sumsq / <double>C) / cx.two_sc
                if not (e < cx.neglogthr):
                    msk[k] = 0
    for n in range(ncon):
        if crow[n] < 0 and occmode == 3:
            continue        # FGD: no pattern needed
        idx = cidx[n]
        s = crow[n] if crow[n] >= 0 else -1 - crow[n]
        x = <int>(pkey[idx] & LOW32)
        msk = mbuf + <int64_t>n * K
        vals = vbuf + <int64_t>n * K * C
        if pattern == 0:
            if uniform:
                pv = cx.pat + _pidx(x, s) * C
                for k in range(K):
                    if msk[k]:
                        for c in range(C):
                            vals[k * C + c] = pv[c]
            else:
                pv = cx.pat + _pidx(x - hmax, r) * C
                for k in range(K):
                    if msk[k]:
                        for c in range(C):
                            vals[k * C + c] = pv[k * C + c]
        elif uniform:
            for k in range(K):
                if msk[k]:
                    for c in range(C):
                        vals[k * C + c] = cx.uvals[idx * C + c]
    if pattern == 1 and not uniform:
        for c in range(C):
            _build_all(cx, c, r, tabs)
            for n in range(ncon):
                if crow[n] < 0 and occmode == 3:
                    continue
                idx = cidx[n]
                x = <int>(pkey[idx] & LOW32)
                d = vpp_u2f(<uint32_t>(pkey[idx] >> 32))
                cn = <int>floor(<double>x - d + 0.5)
                msk = mbuf + <int64_t>n * K
                vals = vbuf + <int64_t>n * K * C
                for k in range(K):
                    if msk[k]:
                        vals[k * C + c] = _hist_value(cx, c, r, tabs, x + k - hmax, cn + k - hmax)
    # 3. right row: pattern of visible points (splatted)
    for n in range(ncon):
        if crow[n] < 0 and occmode == 3:
            continue
        idx = cidx[n]
        x = <int>(pkey[idx] & LOW32)
        d = vpp_u2f(<uint32_t>(pkey[idx] >> 32))
        xp = <double>x - d
        msk = mbuf + <int64_t>n * K
        vals = vbuf + <int64_t>n * K * C
        if splat:
            fl = <int>floor(xp)
            beta = xp - <double>fl
            w0 = _w16(alpha * (1.0 - beta))
            w1 = _w16(alpha * beta)
            for k in range(K):
                if not msk[k]:
                    continue
                col = fl + k - hmax
                if col >= 0 and col < W:
                    for c in range(C):
                        oR[col * C + c] = _blend16(oR[col * C + c], vals[k * C + c], w0)
                col = col + 1
                if beta > 0 and col >= 0 and col < W:
                    for c in range(C):
                        oR[col * C + c] = _blend16(oR[col * C + c], vals[k * C + c], w1)
        else:
            cn = <int>floor(xp + 0.5)
            for k in range(K):
                col = cn + k - hmax
                if msk[k] and col >= 0 and col < W:
                    for c in range(C):
                        oR[col * C + c] = _blend16(oR[col * C + c], vals[k * C + c], wa)
    # 4. left row: pattern, or FGD content of the final right row
    for n in range(ncon):
        idx = cidx[n]
        x = <int>(pkey[idx] & LOW32)
        msk = mbuf + <int64_t>n * K
        if crow[n] < 0 and occmode == 3:
            d = vpp_u2f(<uint32_t>(pkey[idx] >> 32))
            xp = <double>x - d
            if splat:
                fl = <int>floor(xp)
                beta = xp - <double>fl
            else:
                fl = <int>floor(xp + 0.5)
                beta = 0.0
            wb = _w16(beta)
            for k in range(K):
                if not msk[k]:
                    continue
                col = fl + k - hmax
                if col < 0 or col >= W or (beta > 0 and col + 1 >= W):
                    continue
                xl = x + k - hmax
                _fgd_pixel(oL + xl * C, oR + col * C, C, beta > 0, wb, wa)
        else:
            vals = vbuf + <int64_t>n * K * C
            for k in range(K):
                if msk[k]:
                    xl = x + k - hmax
                    for c in range(C):
                        oL[xl * C + c] = _blend16(oL[xl * C + c], vals[k * C + c], wa)


# ----------------------------------------------------------------- entry points
def hist_pick_bits(const uint64_t[::1] occupancy):
    """Histogram value of a 256-bit occupancy (4 uint64, bit v = bin v filled); -1 if all filled.

    Exposed to test the bit-parallel gap search against the plain reference.
    """
    if occupancy.shape[0] != 4:
        raise ValueError(f"occupancy must have 4 words, got {occupancy.shape[0]}")
    return vpp_hist_pick(&occupancy[0])


def _row_keys(const float[:, ::1] disp, int nthreads):
    """Phases A-C: per-row stats, offsets and (d, x)-sorted keys (scanner shared with ``_sweep``)."""
    cdef int H = disp.shape[0], W = disp.shape[1]
    cdef int y, n
    stats = np.empty((H, 4), np.int64)
    cdef int64_t[:, ::1] st = stats
    cdef uint64_t* scratch = NULL
    cdef int* ibuf = NULL
    with nogil, parallel(num_threads=nthreads):
        scratch = <uint64_t*>malloc(sizeof(uint64_t) * (W if W > 0 else 1))
        for y in prange(H, schedule="static"):
            vpp_scan_row(&disp[y, 0], W, scratch, &st[y, 0])
        free(scratch)
    off_np = np.zeros(H + 1, np.int64)
    np.cumsum(stats[:, 1], out=off_np[1:])
    pkey_np = np.empty(max(int(off_np[H]), 1), np.uint64)
    cdef uint64_t[::1] pk = pkey_np
    cdef int64_t[::1] off = off_np
    with nogil, parallel(num_threads=nthreads):
        scratch = <uint64_t*>malloc(sizeof(uint64_t) * (W + 1))
        ibuf = <int*>malloc(sizeof(int) * (2 * W + 2))
        for y in prange(H, schedule="guided"):
            n = vpp_scan_row(&disp[y, 0], W, &pk[0] + off[y], &st[y, 0])
            vpp_sort_keys(&pk[0] + off[y], n, scratch, ibuf, ibuf + W + 1)
        free(scratch)
        free(ibuf)
    return stats, off_np, pkey_np


def project_kernel(const uint8_t[:, :, ::1] left, const uint8_t[:, :, ::1] right,
                   const float[:, ::1] disp, uint8_t[:, :, ::1] out_left,
                   uint8_t[:, :, ::1] out_right, uint8_t[:, ::1] occ,
                   int pattern, bint uniform, int hmax, double alpha, bint splat, int occmode,
                   bint adaptive_distance, double adaptive_gamma, double adaptive_dmax,
                   bint bilateral, double two_ss, double two_sc, double neglogthr,
                   int search_width, int search_height, const uint8_t[::1] pat, int nthreads):
    """Phases A-C, E, F for the variants the sweep kernel does not paint.

    occmode: 0 off, 1 no, 2 bkgd, 3 fgd; ``occ`` is the occlusion mask already
    computed by ``_sweep`` (ignored when occmode is 0).  Returns the row stats.
    """
    cdef int H = disp.shape[0], W = disp.shape[1], C = left.shape[2]
    cdef int y, K = 2 * hmax + 1
    cdef Ctx cx
    stats, off_np, pkey_np = _row_keys(disp, nthreads)
    cdef int64_t n = off_np[H]
    cdef uint64_t[::1] pk = pkey_np
    cdef int64_t[::1] off = off_np
    hp_np = None
    cdef int8_t[::1] hp
    cdef double dmin, dmax, u
    cdef int64_t i
    cx.hp = NULL
    if adaptive_distance and n > 0:
        hp_np = np.empty(n, np.int8)
        hp = hp_np
        starts, stops = off_np[:H], off_np[1:]
        nz = stops > starts
        firsts = pkey_np[starts[nz]] >> np.uint64(32)
        lasts = pkey_np[stops[nz] - 1] >> np.uint64(32)
        dmin = float(firsts.astype(np.uint32).view(np.float32).min())
        dmax = float(lasts.astype(np.uint32).view(np.float32).max())
        if adaptive_dmax > 0:
            dmax = adaptive_dmax
        for i in prange(n, nogil=True, num_threads=nthreads, schedule="static"):
            if dmax <= dmin:
                hp[i] = hmax
            else:
                u = (<double>vpp_u2f(<uint32_t>(pk[i] >> 32)) - dmin) / (dmax - dmin)
                if u < 0:
                    u = 0
                if u > 1:
                    u = 1
                hp[i] = <int8_t>floor(pow(u, adaptive_gamma) * hmax + 0.5)
        cx.hp = &hp[0]
    cx.L = &left[0, 0, 0]
    cx.R = &right[0, 0, 0]
    cx.oL = &out_left[0, 0, 0]
    cx.oR = &out_right[0, 0, 0]
    cx.occ = &occ[0, 0] if occmode != 0 else NULL
    cx.pkey = &pk[0]
    cx.off = &off[0]
    cx.uvals = NULL
    cx.H = H
    cx.W = W
    cx.C = C
    cx.hmax = hmax
    cx.pattern = pattern
    cx.uniform = uniform
    cx.splat = splat
    cx.occmode = occmode
    cx.bilateral = bilateral
    cx.two_ss = two_ss
    cx.two_sc = two_sc
    cx.neglogthr = neglogthr
    cx.alpha = alpha
    cx.wa = _w16(alpha)
    cx.pat = &pat[0]
    cx.sw_half = search_width // 2
    cx.sw_len = search_width
    cx.sh_half = search_height // 2
    cdef int64_t tabsize = 16 * <int64_t>W if pattern == 1 else 1
    cdef uint64_t* tabs = NULL
    uvals_np = None
    cdef uint8_t[::1] uv
    if pattern == 1 and uniform and n > 0:
        uvals_np = np.empty(n * C, np.uint8)
        uv = uvals_np
        with nogil, parallel(num_threads=nthreads):
            tabs = <uint64_t*>malloc(sizeof(uint64_t) * tabsize)
            for y in prange(H, schedule="guided"):
                _uniform_hist_row(&cx, y, tabs, &uv[0])
            free(tabs)
        cx.uvals = &uv[0]
    # contributions to a row come from at most K source rows
    maxcon = max(1, min(int(n), K * int(stats[:, 1].max()) if H > 0 else 0))
    cdef int64_t mc = maxcon
    cdef int64_t* heads = NULL
    cdef int64_t* ends = NULL
    cdef int64_t* cidx = NULL
    cdef int32_t* crow = NULL
    cdef uint8_t* vbuf = NULL
    cdef uint8_t* mbuf = NULL
    with nogil, parallel(num_threads=nthreads):
        heads = <int64_t*>malloc(sizeof(int64_t) * K)
        ends = <int64_t*>malloc(sizeof(int64_t) * K)
        cidx = <int64_t*>malloc(sizeof(int64_t) * mc)
        crow = <int32_t*>malloc(sizeof(int32_t) * mc)
        vbuf = <uint8_t*>malloc(mc * K * C)
        mbuf = <uint8_t*>malloc(mc * K)
        tabs = <uint64_t*>malloc(sizeof(uint64_t) * tabsize)
        for y in prange(H, schedule="guided"):
            _paint_row(&cx, y, heads, ends, cidx, crow, vbuf, mbuf, tabs)
        free(heads)
        free(ends)
        free(cidx)
        free(crow)
        free(vbuf)
        free(mbuf)
        free(tabs)
    return stats
