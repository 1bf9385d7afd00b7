/* The C of the VPP kernel (vpp_service/vpp/_sweep.pyx): the row scanner, the
 * band sort, the occlusion screen, the byte blends on 16-byte vectors, the
 * histogram value source, the named modes and the scratch pool.
 *
 * Every function computes exactly what its scalar definition says.  The SIMD
 * versions are chosen at compile time: AVX2 in the x86-64-v3 build
 * (_sweep_avx2.pyx, __AVX2__ defined), SSE2 (always present on x86-64) in the
 * portable build, a plain C loop elsewhere.  The blend is the library's fixed-point rule
 *     blend(a, b, w) = (a * (65536 - w) + b * w + 32768) >> 16,   0 <= w <= 65536
 * rewritten as a + floor(((b - a) * w + 32768) / 65536) so that it runs on
 * 16-bit lanes: floor(P / 65536) is the signed high half of P = (b - a) * w and
 * the rounding term is bit 15 of its low half.  w = 65536 gives the same bytes
 * as w = 65535 (for |b - a| <= 255), so weights are clamped to 16 bits.
 */
#ifndef VPP_SWEEP_H
#define VPP_SWEEP_H

#include <stdint.h>
#include <string.h>
#include <math.h>
#include <algorithm>
#include <atomic>

#if defined(__AVX2__)
#include <immintrin.h>
#endif
#if defined(__SSE2__)
#include <emmintrin.h>
#define VPP_HAVE_SSE2 1
#else
#define VPP_HAVE_SSE2 0
#endif

static inline uint32_t vpp_sw_f2u(float f) { uint32_t u; memcpy(&u, &f, 4); return u; }

/* Scan one disparity row.  Writes the key (float_bits(d) << 32) | x of every
 * valid point (0 < d < W, finite) in increasing x and returns their number;
 * st = [given, valid, invalid, left-border] where "given" is any value other
 * than +-0 and NaN.  keys must hold W entries.  On SSE2, 8 entries are
 * classified at once and blocks without a given value cost one test (sparse
 * maps are mostly zeros). */
static inline void vpp_scan_one(const float* d, int x, int W, uint64_t* keys, int* n,
                                int64_t* given, int64_t* oob) {
    float v = d[x];
    if (v != 0.0f && v == v) {
        (*given)++;
        if (v > 0.0f && v < (float)W) {
            keys[(*n)++] = ((uint64_t)vpp_sw_f2u(v) << 32) | (uint64_t)x;
            if ((double)x - (double)v < 0.0) (*oob)++;
        }
    }
}

/* The scalar tail [x, W) of a row scan and its statistics (see vpp_scan_row). */
static inline int vpp_scan_finish(const float* d, int x, int W, uint64_t* keys, int n,
                                  int64_t given, int64_t oob, int64_t* st) {
    for (; x < W; x++) vpp_scan_one(d, x, W, keys, &n, &given, &oob);
    st[0] = given;
    st[1] = n;
    st[2] = given - n;
    st[3] = oob;
    return n;
}

static inline int vpp_scan_row(const float* d, int W, uint64_t* keys, int64_t* st) {
    int64_t given = 0, oob = 0;
    int n = 0, x = 0;
#if VPP_HAVE_SSE2
    const __m128 zero = _mm_setzero_ps(), wf = _mm_set1_ps((float)W);
    for (; x + 8 <= W; x += 8) {
        __m128 a = _mm_loadu_ps(d + x), b = _mm_loadu_ps(d + x + 4);
        unsigned g = (unsigned)_mm_movemask_ps(_mm_and_ps(_mm_cmpneq_ps(a, zero), _mm_cmpord_ps(a, a)))
                   | ((unsigned)_mm_movemask_ps(_mm_and_ps(_mm_cmpneq_ps(b, zero), _mm_cmpord_ps(b, b))) << 4);
        unsigned m;
        if (!g) continue;
        m = (unsigned)_mm_movemask_ps(_mm_and_ps(_mm_cmpgt_ps(a, zero), _mm_cmplt_ps(a, wf)))
          | ((unsigned)_mm_movemask_ps(_mm_and_ps(_mm_cmpgt_ps(b, zero), _mm_cmplt_ps(b, wf))) << 4);
        given += __builtin_popcount(g);
        while (m) {
            int i = x + __builtin_ctz(m);
            m &= m - 1;
            keys[n++] = ((uint64_t)vpp_sw_f2u(d[i]) << 32) | (uint64_t)i;
            oob += ((double)i - (double)d[i] < 0.0);
        }
    }
#endif
    return vpp_scan_finish(d, x, W, keys, n, given, oob, st);
}

/* The same scan, for a keys buffer of W entries of which those past the
 * returned count may be overwritten (the sweep's per-row ring).  With AVX2 it
 * is branch-free: each block of 8 is compressed with a permutation from a
 * 256-entry table (vpp_scan_lut, built by vpp_scan_init) and its 8 keys are
 * stored whole, the count advancing by the block's number of points; a write
 * never passes x + 8 <= W because a row has at most one key per pixel. */
#if defined(__AVX2__)
static int32_t vpp_scan_lut[256][8] __attribute__((aligned(32)));
#endif

static inline void vpp_scan_init(void) {
#if defined(__AVX2__)
    int m, b, k;
    for (m = 0; m < 256; m++) {
        for (b = 0, k = 0; b < 8; b++) if (m >> b & 1) vpp_scan_lut[m][k++] = b;
        for (; k < 8; k++) vpp_scan_lut[m][k] = 0;
    }
#endif
}

static inline int vpp_scan_row_w(const float* d, int W, uint64_t* keys, int64_t* st) {
#if defined(__AVX2__)
    int64_t given = 0, oob = 0;
    int n = 0, x = 0;
    const __m256 zero = _mm256_setzero_ps(), wf = _mm256_set1_ps((float)W);
    const __m256 iota = _mm256_setr_ps(0, 1, 2, 3, 4, 5, 6, 7);
    const __m256i iotai = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
    /* given / left-border counts per lane (a compare mask is -1 per counted lane) */
    __m256i gacc = _mm256_setzero_si256(), oacc = _mm256_setzero_si256();
    __m256 xf = iota;
    for (; x + 8 <= W; x += 8, xf = _mm256_add_ps(xf, _mm256_set1_ps(8.0f))) {
        __m256 a = _mm256_loadu_ps(d + x);
        __m256 valid = _mm256_and_ps(_mm256_cmp_ps(a, zero, _CMP_GT_OQ), _mm256_cmp_ps(a, wf, _CMP_LT_OQ));
        unsigned m = (unsigned)_mm256_movemask_ps(valid);
        __m256i perm = _mm256_load_si256((const __m256i*)vpp_scan_lut[m]);
        gacc = _mm256_sub_epi32(gacc, _mm256_castps_si256(_mm256_cmp_ps(a, zero, _CMP_NEQ_OQ)));  /* not 0, not NaN */
        oacc = _mm256_sub_epi32(oacc, _mm256_castps_si256(_mm256_and_ps(_mm256_cmp_ps(xf, a, _CMP_LT_OQ), valid)));
        __m256i xs = _mm256_permutevar8x32_epi32(_mm256_add_epi32(_mm256_set1_epi32(x), iotai), perm);
        __m256i ds = _mm256_permutevar8x32_epi32(_mm256_castps_si256(a), perm);
        __m256i lo = _mm256_unpacklo_epi32(xs, ds), hi = _mm256_unpackhi_epi32(xs, ds);
        _mm256_storeu_si256((__m256i*)(keys + n), _mm256_permute2x128_si256(lo, hi, 0x20));
        _mm256_storeu_si256((__m256i*)(keys + n + 4), _mm256_permute2x128_si256(lo, hi, 0x31));
        n += __builtin_popcount(m);
    }
    {
        int32_t gl[8], ol[8], k;
        _mm256_storeu_si256((__m256i*)gl, gacc);
        _mm256_storeu_si256((__m256i*)ol, oacc);
        for (k = 0; k < 8; k++) {
            given += gl[k];
            oob += ol[k];
        }
    }
    return vpp_scan_finish(d, x, W, keys, n, given, oob, st);
#else
    return vpp_scan_row(d, W, keys, st);
#endif
}

static inline float vpp_sw_u2f(uint32_t u) { float f; memcpy(&f, &u, 4); return f; }

static inline uint32_t vpp_w16(double w) { return (uint32_t)(int64_t)(w * 65536.0 + 0.5); }

/* Per-point geometry of a row's keys (see _sweep.pyx), into arrays of n (+3
 * for the vector tail) entries:
 *   xw[i] = x - round_half_up(d), the warp column (if xw != NULL);
 *   fl[i], w[i] = w0 | w1 << 32 (if fl != NULL): with splatting fl = floor(x'),
 *   beta = x' - fl, w1 = w16(alpha beta) (0 if beta == 0), w0 = w16(alpha (1 - beta));
 *   without, fl = floor(x' + 0.5), w0 = wa, w1 = 0; x' = x - d in double.
 * The AVX2 path does the same double operations 4 points at a time. */
static inline void vpp_geometry(const uint64_t* keys, int n, int32_t* xw, int32_t* fl, uint64_t* w,
                                int splat, double alpha, uint32_t wa) {
    int i = 0;
#if defined(__AVX2__)
    const __m256d half = _mm256_set1_pd(0.5), one = _mm256_set1_pd(1.0), zero = _mm256_setzero_pd();
    const __m256d av = _mm256_set1_pd(alpha), scale = _mm256_set1_pd(65536.0);
    const __m256i pick = _mm256_setr_epi32(0, 2, 4, 6, 1, 3, 5, 7);
    for (; i + 4 <= n; i += 4) {
        /* 4 keys -> x (low halves) and float bits of d (high halves) */
        __m256i k = _mm256_permutevar8x32_epi32(_mm256_loadu_si256((const __m256i*)(keys + i)), pick);
        __m128i x4 = _mm256_castsi256_si128(k);
        __m256d dd = _mm256_cvtps_pd(_mm_castsi128_ps(_mm256_extracti128_si256(k, 1)));
        __m256d xd = _mm256_cvtepi32_pd(x4);
        if (xw) _mm_storeu_si128((__m128i*)(xw + i),
                                 _mm_sub_epi32(x4, _mm256_cvttpd_epi32(_mm256_add_pd(dd, half))));
        if (fl) {
            __m256d xp = _mm256_sub_pd(xd, dd), f, beta;
            __m128i w0, w1;
            if (splat) {
                f = _mm256_floor_pd(xp);
                beta = _mm256_sub_pd(xp, f);
                w1 = _mm256_cvttpd_epi32(_mm256_add_pd(_mm256_mul_pd(_mm256_mul_pd(av, beta), scale), half));
                w1 = _mm_and_si128(w1, _mm256_castsi256_si128(_mm256_permutevar8x32_epi32(
                    _mm256_castpd_si256(_mm256_cmp_pd(beta, zero, _CMP_GT_OQ)), pick)));
                w0 = _mm256_cvttpd_epi32(_mm256_add_pd(_mm256_mul_pd(_mm256_mul_pd(
                    av, _mm256_sub_pd(one, beta)), scale), half));
            } else {
                f = _mm256_floor_pd(_mm256_add_pd(xp, half));
                w0 = _mm_set1_epi32((int)wa);
                w1 = _mm_setzero_si128();
            }
            _mm_storeu_si128((__m128i*)(fl + i), _mm256_cvttpd_epi32(f));
            _mm_storeu_si128((__m128i*)(w + i), _mm_unpacklo_epi32(w0, w1));
            _mm_storeu_si128((__m128i*)(w + i + 2), _mm_unpackhi_epi32(w0, w1));
        }
    }
#endif
    for (; i < n; i++) {
        double x = (double)(uint32_t)(keys[i] & 0xFFFFFFFFu);
        double d = (double)vpp_sw_u2f((uint32_t)(keys[i] >> 32));
        if (xw) xw[i] = (int32_t)x - (int32_t)(d + 0.5);
        if (fl) {
            double xp = x - d, f, beta;
            uint32_t w0, w1;
            if (splat) {
                f = floor(xp);
                beta = xp - f;
                w1 = beta > 0 ? vpp_w16(alpha * beta) : 0;
                w0 = vpp_w16(alpha * (1.0 - beta));
            } else {
                f = floor(xp + 0.5);
                w0 = wa;
                w1 = 0;
            }
            fl[i] = (int32_t)f;
            w[i] = (uint64_t)w0 | ((uint64_t)w1 << 32);
        }
    }
}


/* One point of a paint band (see _paint_band in _sweep.pyx). */
typedef struct {
    int32_t x;
    int32_t s;          /* image row */
    int32_t fl;         /* right-view column (see vpp_geometry) */
    uint32_t w0;
    uint32_t w1;
    int16_t occl;       /* occluded (flag of vpp_occ_screen) */
    int16_t h;          /* patch half-size (adaptive) */
    int32_t vi;         /* index in gather order (its values in the band's value buffer) */
    float d;
} vpp_band_pt;

/* Stable insertion sort by d; a point already in place costs one compare. */
static inline void vpp_band_insertion_sort(vpp_band_pt* a, int n) {
    int i, j;
    for (i = 1; i < n; i++) {
        if (a[i - 1].d > a[i].d) {
            vpp_band_pt v = a[i];
            for (j = i; j > 0 && a[j - 1].d > v.d; j--) a[j] = a[j - 1];
            a[j] = v;
        }
    }
}

struct vpp_band_pt_less {
    bool operator()(const vpp_band_pt& a, const vpp_band_pt& b) const { return a.d < b.d; }
};

/* Stable sort of a band's points by d into out: in holds them in gather
 * order (row, then x), so a stable sort by d gives the global paint order
 * (d, y, x).  A bucket sort on the points themselves (no key array, no
 * permutation pass afterwards), cheap on the bands' few thousand points:
 *   1. bucket b = min(floor((d - dmin) * 2n / (dmax - dmin)), 2n - 1) in float,
 *      8 points a vector (float subtraction and scaling by a positive
 *      constant never reverse two values, so buckets are in d order);
 *   2. count, prefix, scatter in input order (stable);
 *   3. one insertion pass over the whole array puts each bucket in order
 *      (2n buckets hold about half a point each, so it rarely moves anything
 *      and its branch is predictable); a crowded bucket (> 32) gets
 *      std::stable_sort first.
 * dv: the points' d (n floats);
 * dmin, dmax: their extremes.  Scratch: bucket holds n entries, cnt 2n + 1. */
static inline void vpp_sort_band(const vpp_band_pt* in, const float* dv, int n, float dmin, float dmax,
                                 vpp_band_pt* out, int* bucket, int* cnt) {
    const int nb = 2 * n;
    double scale_d = (double)nb / ((double)dmax - (double)dmin);
    float scale, top;
    int i, b, s, e, crowded = 0;
    if (n <= 24 || dmin == dmax || !(scale_d < 1e30) || nb >= (1 << 24)) {   /* float bucket ids exact below 2^24 */
        memcpy(out, in, sizeof(vpp_band_pt) * (size_t)n);
        if (dmin == dmax) return;
        if (n <= 24) {
            vpp_band_insertion_sort(out, n);
        } else {
            std::stable_sort(out, out + n, vpp_band_pt_less());
        }
        return;
    }
    scale = (float)scale_d;
    top = (float)(nb - 1);
    i = 0;
#if defined(__AVX2__)
    {
        const __m256 vmin = _mm256_set1_ps(dmin), vs = _mm256_set1_ps(scale), vt = _mm256_set1_ps(top);
        for (; i + 8 <= n; i += 8) {
            __m256 t = _mm256_min_ps(_mm256_mul_ps(_mm256_sub_ps(_mm256_loadu_ps(dv + i), vmin), vs), vt);
            _mm256_storeu_si256((__m256i*)(bucket + i), _mm256_cvttps_epi32(t));
        }
    }
#elif VPP_HAVE_SSE2
    {
        const __m128 vmin = _mm_set1_ps(dmin), vs = _mm_set1_ps(scale), vt = _mm_set1_ps(top);
        for (; i + 4 <= n; i += 4) {
            __m128 t = _mm_min_ps(_mm_mul_ps(_mm_sub_ps(_mm_loadu_ps(dv + i), vmin), vs), vt);
            _mm_storeu_si128((__m128i*)(bucket + i), _mm_cvttps_epi32(t));
        }
    }
#endif
    for (; i < n; i++) {
        float t = (dv[i] - dmin) * scale;
        bucket[i] = (int)(t < top ? t : top);
    }
    memset(cnt, 0, sizeof(int) * (size_t)(nb + 1));
    for (i = 0; i < n; i++) cnt[bucket[i] + 1]++;
    for (i = 0; i < nb; i++) {
        crowded |= cnt[i + 1] > 32;
        cnt[i + 1] += cnt[i];
    }
    for (i = 0; i < n; i++) out[cnt[bucket[i]]++] = in[i];   /* cnt[b] ends at bucket b's end */
    if (crowded) {
        s = 0;
        for (b = 0; b < nb; b++) {
            e = cnt[b];
            if (e - s > 32) {
                std::stable_sort(out + s, out + e, vpp_band_pt_less());
            }
            s = e;
        }
    }
    vpp_band_insertion_sort(out, n);
}

/* Occlusion screen of one row's points (see _classify in _sweep.pyx).  The
 * warp is column-major: cell (column c, ring slot l) at warp0[c * WL + l]
 * (c counted from image column 0, may be negative).  For point i (d from
 * keys[i], warp column xw[i]) writes out[i] = 1 if it lost a collision in its
 * own cell (warp0[xw * WL + lq] > d), else 2 if some window cell passes the
 * float screen
 *     f32(w - pen_f) > thr,   thr = f32(d + t - (d + t + penmax + 1) 2^-20),
 * i.e. warp0[(xw - rx2 + j) * WL + l] - pv[j * WL + l] > thr for a window
 * column j < nwin and a slot l (pv is +inf for slots outside the window and
 * at the point's own cell; empty cells are -inf: neither ever passes), else 0.
 * Points marked 2 are then tested exactly (double, as the reference).  The
 * screen never misses a cell with (w - d) - pen > t in double: pen_f, the
 * difference and thr are each rounded to float with a relative error below
 * 2^-24, in all at most 2^-24 (3 pen + 2 (d + t) + ...), and the margin is 16
 * times that.  With AVX2 and an 8-slot ring (windows up to 7 rows) a window
 * column is one vector: the running maximum of w - pen_f over the nwin
 * columns, one compare per point; the default 9-column window keeps its 9
 * penalty vectors in registers. */
static inline float vpp_occ_thr(double d, double t, double penmax) {
    return (float)(d + t - (d + t + penmax + 1.0) * 9.5367431640625e-07);
}

static inline void vpp_occ_screen(const uint64_t* keys, const int32_t* xw, int n, const float* warp0, int WL,
                                  int lq, const float* pv, int nwin, int rx2, double t, double penmax,
                                  uint8_t* out) {
    int i, l;
#if defined(__AVX2__)
    if (WL == 8 && nwin == 9) {
        const __m256 q0 = _mm256_loadu_ps(pv), q1 = _mm256_loadu_ps(pv + 8), q2 = _mm256_loadu_ps(pv + 16);
        const __m256 q3 = _mm256_loadu_ps(pv + 24), q4 = _mm256_loadu_ps(pv + 32), q5 = _mm256_loadu_ps(pv + 40);
        const __m256 q6 = _mm256_loadu_ps(pv + 48), q7 = _mm256_loadu_ps(pv + 56), q8 = _mm256_loadu_ps(pv + 64);
        for (i = 0; i < n; i++) {
            const float d = vpp_sw_u2f((uint32_t)(keys[i] >> 32));
            const int64_t o = xw[i];
            const float* c = warp0 + (o - rx2) * 8;
            __m256 a, b;
            if (warp0[o * 8 + lq] > d) { out[i] = 1; continue; }
            a = _mm256_max_ps(_mm256_sub_ps(_mm256_loadu_ps(c), q0), _mm256_sub_ps(_mm256_loadu_ps(c + 8), q1));
            b = _mm256_max_ps(_mm256_sub_ps(_mm256_loadu_ps(c + 16), q2), _mm256_sub_ps(_mm256_loadu_ps(c + 24), q3));
            a = _mm256_max_ps(a, _mm256_max_ps(_mm256_sub_ps(_mm256_loadu_ps(c + 32), q4),
                                               _mm256_sub_ps(_mm256_loadu_ps(c + 40), q5)));
            b = _mm256_max_ps(b, _mm256_max_ps(_mm256_sub_ps(_mm256_loadu_ps(c + 48), q6),
                                               _mm256_sub_ps(_mm256_loadu_ps(c + 56), q7)));
            a = _mm256_max_ps(_mm256_max_ps(a, b), _mm256_sub_ps(_mm256_loadu_ps(c + 64), q8));
            out[i] = _mm256_movemask_ps(_mm256_cmp_ps(a, _mm256_set1_ps(vpp_occ_thr(d, t, penmax)),
                                                      _CMP_GT_OQ)) ? 2 : 0;
        }
        return;
    }
#endif
    for (i = 0; i < n; i++) {
        const float d = vpp_sw_u2f((uint32_t)(keys[i] >> 32));
        const int64_t o = xw[i];
        const float* c = warp0 + (o - rx2) * WL;
        const int cells = nwin * WL;
        float thr;
        int pass = 0;
        if (warp0[o * WL + lq] > d) { out[i] = 1; continue; }
        thr = vpp_occ_thr(d, t, penmax);
        l = 0;
#if defined(__AVX2__)
        if (WL % 8 == 0) {
            __m256 m = _mm256_set1_ps(-INFINITY);
            for (; l < cells; l += 8)
                m = _mm256_max_ps(m, _mm256_sub_ps(_mm256_loadu_ps(c + l), _mm256_loadu_ps(pv + l)));
            pass = _mm256_movemask_ps(_mm256_cmp_ps(m, _mm256_set1_ps(thr), _CMP_GT_OQ));
        }
#endif
#if VPP_HAVE_SSE2
        if (l == 0 && WL % 4 == 0) {
            __m128 m = _mm_set1_ps(-INFINITY);
            for (; l < cells; l += 4)
                m = _mm_max_ps(m, _mm_sub_ps(_mm_loadu_ps(c + l), _mm_loadu_ps(pv + l)));
            pass = _mm_movemask_ps(_mm_cmpgt_ps(m, _mm_set1_ps(thr)));
        }
#endif
        for (; l < cells && !pass; l++)            /* the window's columns are contiguous */
            pass = c[l] - pv[l] > thr;
        out[i] = pass ? 2 : 0;
    }
}

static inline uint8_t vpp_blend_u8(uint32_t a, uint32_t b, uint32_t w) {
    return (uint8_t)((a * (65536u - w) + b * w + 32768u) >> 16);
}

#if VPP_HAVE_SSE2
static inline __m128i vpp_blend_epi16(__m128i a, __m128i b, __m128i w) {
    __m128i d = _mm_sub_epi16(b, a);
    __m128i hi = _mm_mulhi_epu16(d, w);                     /* high half of (d mod 2^16) * w */
    hi = _mm_sub_epi16(hi, _mm_and_si128(_mm_srai_epi16(d, 15), w));   /* signed correction */
    __m128i rb = _mm_srli_epi16(_mm_mullo_epi16(d, w), 15);  /* low half >= 32768 */
    return _mm_add_epi16(_mm_add_epi16(a, hi), rb);
}

/* Byte lanes lo <= i < hi of a 16-byte vector (all ones there, zero elsewhere). */
static inline __m128i vpp_lanes(int lo, int hi) {
    const __m128i iota = _mm_setr_epi8(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    return _mm_and_si128(_mm_cmpgt_epi8(iota, _mm_set1_epi8((char)(lo - 1))),
                         _mm_cmplt_epi8(iota, _mm_set1_epi8((char)hi)));
}

/* (alo, ahi) = 16 bytes widened to 16 bits; blend the lanes of `lanes` with b. */
static inline void vpp_blend_regs(__m128i* alo, __m128i* ahi, __m128i b, __m128i lanes,
                                  uint32_t w) {
    const __m128i z = _mm_setzero_si128();
    __m128i wv = _mm_set1_epi16((short)(uint16_t)(w > 65535u ? 65535u : w));
    *alo = vpp_blend_epi16(*alo, _mm_unpacklo_epi8(b, z), _mm_and_si128(wv, _mm_unpacklo_epi8(lanes, lanes)));
    *ahi = vpp_blend_epi16(*ahi, _mm_unpackhi_epi8(b, z), _mm_and_si128(wv, _mm_unpackhi_epi8(lanes, lanes)));
}

/* Blend bytes [0, n) (n <= 16) of the 16 bytes at dst with val; bytes [n, 16)
 * are rewritten unchanged, so all 16 must belong to the caller. */
static inline void vpp_blend16(uint8_t* dst, const uint8_t* val, int n, uint32_t w) {
    const __m128i z = _mm_setzero_si128();
    __m128i a = _mm_loadu_si128((const __m128i*)dst);
    __m128i alo = _mm_unpacklo_epi8(a, z), ahi = _mm_unpackhi_epi8(a, z);
    vpp_blend_regs(&alo, &ahi, _mm_loadu_si128((const __m128i*)val), vpp_lanes(0, n), w);
    _mm_storeu_si128((__m128i*)dst, _mm_packus_epi16(alo, ahi));
}
#if defined(__AVX2__)
/* AVX2 versions (16 byte lanes widened into one 256-bit register), used by the
 * build compiled for x86-64-v3 (_sweep_avx2); same arithmetic, same bytes. */
#include <immintrin.h>

static inline __m256i vpp_lanes16_avx2(int lo, int hi) {
    const __m256i iota = _mm256_setr_epi16(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    return _mm256_and_si256(_mm256_cmpgt_epi16(iota, _mm256_set1_epi16((short)(lo - 1))),
                            _mm256_cmpgt_epi16(_mm256_set1_epi16((short)hi), iota));
}

static inline __m256i vpp_blend_avx2(__m256i a, __m256i b, __m256i lanes, uint32_t w) {
    __m256i wv = _mm256_and_si256(_mm256_set1_epi16((short)(uint16_t)(w > 65535u ? 65535u : w)), lanes);
    __m256i d = _mm256_sub_epi16(b, a);
    __m256i hi = _mm256_sub_epi16(_mm256_mulhi_epu16(d, wv),
                                  _mm256_and_si256(_mm256_srai_epi16(d, 15), wv));
    __m256i rb = _mm256_srli_epi16(_mm256_mullo_epi16(d, wv), 15);
    return _mm256_add_epi16(_mm256_add_epi16(a, hi), rb);
}

static inline void vpp_store_packed_avx2(uint8_t* dst, __m256i a) {
    _mm_storeu_si128((__m128i*)dst, _mm_packus_epi16(_mm256_castsi256_si128(a),
                                                     _mm256_extracti128_si256(a, 1)));
}

/* The blend with w < 32768 (every weight when alpha <= 0.5): w fits a signed
 * 16-bit lane, so mulhi_epi16 gives floor(d w / 65536) directly and the sign
 * correction of vpp_blend_avx2 is not needed; same bytes. */
static inline __m256i vpp_blend_avx2_s(__m256i a, __m256i b, __m256i wv) {
    __m256i d = _mm256_sub_epi16(b, a);
    return _mm256_add_epi16(_mm256_add_epi16(a, _mm256_mulhi_epi16(d, wv)),
                            _mm256_srli_epi16(_mm256_mullo_epi16(d, wv), 15));
}

/* vpp_splat16 for the nrows rows of one point's patch: row i's span
 * starts at dst + i rs, its pattern at pat + C * ((p0 + i * step) & mask).
 * Lane masks and weights are set up once. */
static inline void vpp_splat_rows_avx2(uint8_t* dst, int64_t rs, const uint8_t* pat, int64_t p0,
                                       int64_t step, int64_t mask, int nrows, int C, int k0, int k1,
                                       uint32_t w0, uint32_t w1) {
    const __m256i l1 = vpp_lanes16_avx2((k0 + 1) * C, (k1 + 1) * C), l0 = vpp_lanes16_avx2(k0 * C, k1 * C);
    const __m256i wv1 = _mm256_and_si256(_mm256_set1_epi16((short)(uint16_t)(w1 > 65535u ? 65535u : w1)), l1);
    const __m256i wv0 = _mm256_and_si256(_mm256_set1_epi16((short)(uint16_t)(w0 > 65535u ? 65535u : w0)), l0);
    const int fast = w0 < 32768u && w1 < 32768u;
    int i;
    for (i = 0; i < nrows; i++, dst += rs, p0 += step) {
        const uint8_t* val = pat + (size_t)C * (size_t)(p0 & mask);
        __m256i a = _mm256_cvtepu8_epi16(_mm_loadu_si128((const __m128i*)dst));
        __m128i v = _mm_loadu_si128((const __m128i*)val);
        __m256i b1 = _mm256_cvtepu8_epi16(C == 3 ? _mm_slli_si128(v, 3) : _mm_slli_si128(v, 1));
        __m256i b0 = _mm256_cvtepu8_epi16(v);
        if (fast) {
            if (w1) a = vpp_blend_avx2_s(a, b1, wv1);
            a = vpp_blend_avx2_s(a, b0, wv0);
        } else {
            if (w1) a = vpp_blend_avx2(a, b1, l1, w1);
            a = vpp_blend_avx2(a, b0, l0, w0);
        }
        vpp_store_packed_avx2(dst, a);
    }
}

/* One uniform-weight blend of bytes [lo, hi) (hi <= 16) of 16-byte spans,
 * for nrows rows (dst + i rs; pattern as in vpp_splat_rows_avx2, whose
 * bytes [lo, hi) are blended in place). */
static inline void vpp_blend_rows_avx2(uint8_t* dst, int64_t rs, const uint8_t* pat, int64_t p0,
                                       int64_t step, int64_t mask, int nrows, int C, int lo, int hi,
                                       uint32_t w) {
    const __m256i l = vpp_lanes16_avx2(lo, hi);
    const __m256i wv = _mm256_and_si256(_mm256_set1_epi16((short)(uint16_t)(w > 65535u ? 65535u : w)), l);
    int i;
    for (i = 0; i < nrows; i++, dst += rs, p0 += step) {
        const uint8_t* val = pat + (size_t)C * (size_t)(p0 & mask);
        __m256i a = _mm256_cvtepu8_epi16(_mm_loadu_si128((const __m128i*)dst));
        __m256i b = _mm256_cvtepu8_epi16(_mm_loadu_si128((const __m128i*)val));
        vpp_store_packed_avx2(dst, w < 32768u ? vpp_blend_avx2_s(a, b, wv) : vpp_blend_avx2(a, b, l, w));
    }
}
#define VPP_BUILD_AVX2 1
#else
#define VPP_BUILD_AVX2 0
/* not called without AVX2 (the kernel checks vpp_build_avx2()) */
static inline void vpp_splat_rows_avx2(uint8_t* dst, int64_t rs, const uint8_t* pat, int64_t p0,
                                       int64_t step, int64_t mask, int nrows, int C, int k0, int k1,
                                       uint32_t w0, uint32_t w1) {
    (void)dst; (void)rs; (void)pat; (void)p0; (void)step; (void)mask; (void)nrows; (void)C;
    (void)k0; (void)k1; (void)w0; (void)w1;
}
static inline void vpp_blend_rows_avx2(uint8_t* dst, int64_t rs, const uint8_t* pat, int64_t p0,
                                       int64_t step, int64_t mask, int nrows, int C, int lo, int hi,
                                       uint32_t w) {
    (void)dst; (void)rs; (void)pat; (void)p0; (void)step; (void)mask; (void)nrows; (void)C;
    (void)lo; (void)hi; (void)w;
}
#endif

/* Whether this build uses AVX2, and whether the CPU could run the AVX2 build
 * (AVX2, FMA, BMI1/2, LZCNT, POPCNT: what -march=x86-64-v3 may emit). */
static inline int vpp_build_avx2(void) { return VPP_BUILD_AVX2; }

static inline int vpp_cpu_supports_avx2(void) {
#if defined(__GNUC__) && (defined(__x86_64__) || defined(__i386__))
    __builtin_cpu_init();
    return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma")
        && __builtin_cpu_supports("bmi") && __builtin_cpu_supports("bmi2")
        && __builtin_cpu_supports("popcnt") && __builtin_cpu_supports("f16c")
        && __builtin_cpu_supports("movbe");
#else
    return 0;
#endif
}

/* Splatted right-view paint of one patch row in one pass: pixels [k0, k1) of
 * val (C bytes each) go to columns j = k of dst with weight w0 and, first, to
 * columns j = k + 1 with weight w1 (see _sweep.pyx).  dst is column 0 of the
 * span.  Returns 0 (nothing done) unless the span fits one 16-byte vector
 * ((k1 + 1) * C <= 16, `room` >= 16 bytes to the row end); the caller then
 * blends the two spans separately. */
static inline int vpp_splat16(uint8_t* dst, const uint8_t* val, int C, int k0, int k1,
                              uint32_t w0, uint32_t w1, int64_t room) {
#if VPP_HAVE_SSE2
    const __m128i z = _mm_setzero_si128();
    __m128i a, alo, ahi, v, v1;
    if ((k1 + 1) * C > 16 || room < 16 || (C != 1 && C != 3)) return 0;
#if VPP_BUILD_AVX2
    vpp_splat_rows_avx2(dst, 0, val, 0, 0, 0, 1, C, k0, k1, w0, w1);
    return 1;
#endif
    a = _mm_loadu_si128((const __m128i*)dst);
    alo = _mm_unpacklo_epi8(a, z);
    ahi = _mm_unpackhi_epi8(a, z);
    v = _mm_loadu_si128((const __m128i*)val);
    v1 = C == 3 ? _mm_slli_si128(v, 3) : _mm_slli_si128(v, 1);
    if (w1) vpp_blend_regs(&alo, &ahi, v1, vpp_lanes((k0 + 1) * C, (k1 + 1) * C), w1);
    vpp_blend_regs(&alo, &ahi, v, vpp_lanes(k0 * C, k1 * C), w0);
    _mm_storeu_si128((__m128i*)dst, _mm_packus_epi16(alo, ahi));
    return 1;
#else
    (void)dst; (void)val; (void)C; (void)k0; (void)k1; (void)w0; (void)w1; (void)room;
    return 0;
#endif
}
#endif

/* dst[i] = blend(dst[i], val[i], w) for i < n.  `room` is the number of bytes
 * from dst to the end of the caller's row; val must have n rounded up to 16
 * readable bytes. */
static inline void vpp_blend_span(uint8_t* dst, const uint8_t* val, int n, uint32_t w,
                                  int64_t room) {
    int i;
    if (n <= 0) return;
#if VPP_HAVE_SSE2
    if (room >= (int64_t)((n + 15) & ~15)) {
        uint32_t w16 = w > 65535u ? 65535u : w;
#if VPP_BUILD_AVX2
        for (; n > 0; n -= 16, dst += 16, val += 16) vpp_blend_rows_avx2(dst, 0, val, 0, 0, 0, 1, 1, 0, n < 16 ? n : 16, w16);
        return;
#endif
        for (; n > 0; n -= 16, dst += 16, val += 16) vpp_blend16(dst, val, n < 16 ? n : 16, w16);
        return;
    }
#endif
    for (i = 0; i < n; i++) dst[i] = vpp_blend_u8(dst[i], val[i], w);
}


/* ---- named modes; vpp_service.vpp.params.kernel_params maps a VPPConfig to them */
enum vpp_pattern { VPP_PATTERN_RANDOM = 0, VPP_PATTERN_HISTOGRAM = 1 };
enum vpp_occlusion { VPP_OCC_OFF = 0, VPP_OCC_NO = 1, VPP_OCC_BKGD = 2, VPP_OCC_FGD = 3 };
enum vpp_patch_mask { VPP_MASK_FULL = 0, VPP_MASK_DISTANCE = 1, VPP_MASK_BILATERAL = 2 };

/* ---- per-pixel rules (see vpp_service/vpp/rng.py and tests/vpp_reference.py) */
#define VPP_ROW_STEP 23679      /* rng.ROW_STEP */
#define VPP_TABLE_MASK 65535    /* rng.TABLE_SIZE - 1 */

/* splitmix64 finaliser of seedmix + ((y << 32) | x) * KEY_MUL, seedmix = seed * SEED_MUL */
static inline uint64_t vpp_hash(uint64_t seedmix, uint64_t x, uint64_t y) {
    uint64_t z = seedmix + ((y << 32) | x) * 0x9E3779B97F4A7C15ULL;
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    return z ^ (z >> 31);
}

static inline uint64_t vpp_seedmix(uint64_t seed) { return seed * 0xD1B54A32D192ED03ULL; }

/* Pattern-table index of pixel (x, y).  The kernel's table is padded past
 * TABLE_SIZE entries with a copy of its start, so entry vpp_pidx(x0, y) + k is pixel x0 + k. */
static inline int64_t vpp_pidx(int64_t x, int64_t y) { return (x + y * VPP_ROW_STEP) & VPP_TABLE_MASK; }

static inline int vpp_ifloor(double v) { int i = (int)v; return (double)i > v ? i - 1 : i; }

/* FGD: blend the right view at x' (interpolated between rp and the next pixel
 * with weight wb when interp) into the left pixel lp with weight wa. */
static inline void vpp_fgd_pixel(uint8_t* lp, const uint8_t* rp, int C, int interp, uint64_t wb, uint64_t wa) {
    int c;
    for (c = 0; c < C; c++) {
        uint64_t v16 = interp ? (uint64_t)rp[c] * (65536 - wb) + (uint64_t)rp[C + c] * wb
                              : (uint64_t)rp[c] * 65536;
        lp[c] = (uint8_t)(((uint64_t)lp[c] * (65536 - wa) * 65536 + v16 * wa + 2147483648ULL) >> 32);
    }
}

/* ---- pool of per-thread scratch buffers kept between calls (lock-free slots) */
#define VPP_POOL 64
static std::atomic<void*> vpp_scratch_pool[VPP_POOL];

static inline void* vpp_pool_take(void) {
    for (int i = 0; i < VPP_POOL; i++) {
        void* s = vpp_scratch_pool[i].exchange(nullptr, std::memory_order_acq_rel);
        if (s) return s;
    }
    return nullptr;
}

static inline int vpp_pool_give(void* s) {
    for (int i = 0; i < VPP_POOL; i++) {
        void* expected = nullptr;
        if (vpp_scratch_pool[i].compare_exchange_strong(expected, s, std::memory_order_acq_rel)) return 1;
    }
    return 0;
}

/* ---- histogram value source
 * 256-bit bin occupancy words: bit p is word p >> 6, bit p & 63. */
static inline void vpp_shr256(const uint64_t* a, int s, uint64_t* r) {   /* r[p] = a[p + s] */
    int q = s >> 6, b = s & 63, i;
    if (q == 0) {                                   /* the common case, 0 < s < 64 */
        r[0] = (a[0] >> b) | (a[1] << (64 - b));
        r[1] = (a[1] >> b) | (a[2] << (64 - b));
        r[2] = (a[2] >> b) | (a[3] << (64 - b));
        r[3] = a[3] >> b;
        return;
    }
    for (i = 0; i < 4; i++) {
        uint64_t lo = i + q < 4 ? a[i + q] : 0, hi = i + q + 1 < 4 ? a[i + q + 1] : 0;
        r[i] = b ? (lo >> b) | (hi << (64 - b)) : lo;
    }
}

static inline int vpp_nz256(const uint64_t* a) { return (a[0] | a[1] | a[2] | a[3]) != 0; }

static inline int vpp_ctz256(const uint64_t* a) {
    for (int i = 0; i < 4; i++) if (a[i]) return (i << 6) + __builtin_ctzll(a[i]);
    return 256;
}

static inline int vpp_top256(const uint64_t* a) {   /* highest set bit, -1 if none */
    for (int i = 3; i >= 0; i--) if (a[i]) return (i << 6) + 63 - __builtin_clzll(a[i]);
    return -1;
}

/* The value farthest from every filled bin of o (ties: smallest); -1 if all
 * are filled.  Bit-parallel: P[j] marks the starts of zero runs of length
 * >= 2^j between the first and last filled bins; binary lifting gives the
 * longest run, then the first run whose half-length is the best. */
static inline int vpp_hist_pick(const uint64_t* o) {
    uint64_t Z[4], P[9][4], cur[4], t[4];
    int f1, ls, i, j, top, k, m, rem, best_i = 0, best_d;
    if ((o[0] & o[1] & o[2] & o[3]) == ~0ULL) return -1;
    if (!vpp_nz256(o)) return 0;
    f1 = vpp_ctz256(o);
    ls = vpp_top256(o);
    best_d = f1;                                    /* the run before the first filled bin */
    for (i = 0; i < 4; i++) {                       /* empty bins f1 < p < ls */
        int lo = i << 6;
        uint64_t w = ~o[i];
        if (f1 + 1 > lo) w &= f1 + 1 - lo >= 64 ? 0 : ~0ULL << (f1 + 1 - lo);
        if (ls < lo + 64) w &= ls - lo <= 0 ? 0 : ~0ULL >> (64 - (ls - lo));
        Z[i] = w;
    }
    if (vpp_nz256(Z)) {
        memcpy(P[0], Z, sizeof Z);
        for (top = 0; top < 8; top++) {
            vpp_shr256(P[top], 1 << top, t);
            for (i = 0; i < 4; i++) t[i] &= P[top][i];
            if (!vpp_nz256(t)) break;
            memcpy(P[top + 1], t, sizeof t);
        }
        memcpy(cur, P[top], sizeof cur);
        k = 1 << top;
        for (j = top - 1; j >= 0; j--) {
            vpp_shr256(P[j], k, t);
            for (i = 0; i < 4; i++) t[i] &= cur[i];
            if (vpp_nz256(t)) {
                memcpy(cur, t, sizeof t);
                k += 1 << j;
            }
        }
        m = (k + 1) >> 1;
        if (m > best_d) {                           /* first run of length >= 2m - 1 */
            memcpy(cur, Z, sizeof cur);
            k = 1;
            for (j = 0, rem = 2 * m - 2; rem; j++, rem >>= 1) {
                if (rem & 1) {
                    vpp_shr256(P[j], k, t);
                    for (i = 0; i < 4; i++) cur[i] &= t[i];
                    k += 1 << j;
                }
            }
            best_d = m;
            best_i = vpp_ctz256(cur) - 1 + m;
        }
    }
    if (255 - ls > best_d) best_i = 255;            /* the run after the last filled bin */
    return best_i;
}

static uint64_t vpp_onehot[256][4] __attribute__((aligned(32)));

static inline void vpp_onehot_init(void) {
    for (int v = 0; v < 256; v++) {
        memset(vpp_onehot[v], 0, sizeof vpp_onehot[v]);
        vpp_onehot[v][v >> 6] = (uint64_t)1 << (v & 63);
    }
}

#if !defined(__AVX2__)
typedef uint64_t vpp_v2 __attribute__((vector_size(16)));   /* half an occupancy word */
static inline vpp_v2 vpp_ld2(const uint64_t* p) { vpp_v2 v; memcpy(&v, p, 16); return v; }
static inline void vpp_st2(uint64_t* p, vpp_v2 v) { memcpy(p, &v, 16); }
#endif

/* Per aligned 32-column block, prefix (pre) and suffix (suf) OR of the
 * occupancy of each column over rows r +- sh_half (clipped) of channel c:
 * 4 words per column.  Any window is then suffix | middle blocks | prefix. */
static inline void vpp_hist_tables(const uint8_t* img, int H, int W, int C, int c, int r, int sh_half,
                                   uint64_t* pre, uint64_t* suf) {
    int y0 = r - sh_half > 0 ? r - sh_half : 0, y1 = r + sh_half < H - 1 ? r + sh_half : H - 1;
    const int64_t rs = (int64_t)W * C;
    for (int b0 = 0; b0 < W; b0 += 32) {
        int b1 = b0 + 32 < W ? b0 + 32 : W, x;
#if defined(__AVX2__)
        __m256i acc = _mm256_setzero_si256();
        for (x = b0; x < b1; x++) {
            const uint8_t* p = img + ((int64_t)y0 * W + x) * C + c;
            __m256i a = _mm256_load_si256((const __m256i*)vpp_onehot[p[0]]);
            for (int y = y0 + 1; y <= y1; y++) {
                p += rs;
                a = _mm256_or_si256(a, _mm256_load_si256((const __m256i*)vpp_onehot[p[0]]));
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
#else
        const vpp_v2 zero = {0, 0};
        vpp_v2 acc0 = zero, acc1 = zero;
        for (x = b0; x < b1; x++) {
            const uint8_t* p = img + ((int64_t)y0 * W + x) * C + c;
            vpp_v2 a0 = vpp_ld2(vpp_onehot[p[0]]), a1 = vpp_ld2(vpp_onehot[p[0]] + 2);
            for (int y = y0 + 1; y <= y1; y++) {
                p += rs;
                a0 |= vpp_ld2(vpp_onehot[p[0]]);
                a1 |= vpp_ld2(vpp_onehot[p[0]] + 2);
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
#endif
    }
}

/* The images and window of the histogram source. */
typedef struct {
    const uint8_t* L;
    const uint8_t* R;
    int H, W, C;
    int sw_half, sw_len, sh_half;   /* window columns [cen - sw_half, cen - sw_half + sw_len - 1], rows r +- sh_half */
} vpp_hist_src;

static inline void vpp_or4(uint64_t* o, const uint64_t* t) {
    o[0] |= t[0]; o[1] |= t[1]; o[2] |= t[2]; o[3] |= t[3];
}

/* Clip the window of centre column cen to [a, e] (a > e: empty). */
static inline void vpp_window_cols(const vpp_hist_src* hs, int cen, int* a, int* e) {
    *a = cen - hs->sw_half;
    *e = *a + hs->sw_len - 1;
    if (*a < 0) *a = 0;
    if (*e > hs->W - 1) *e = hs->W - 1;
}

/* OR the occupancy of the window of centre column cen (row r, channel c) into o. */
static inline void vpp_window_or(const vpp_hist_src* hs, const uint8_t* img, int c, int r,
                                 const uint64_t* pre, const uint64_t* suf, int cen, uint64_t* o) {
    int a, e, ba, be, bend;
    vpp_window_cols(hs, cen, &a, &e);
    if (a > e) return;
    ba = a >> 5;
    be = e >> 5;
    if (ba < be) {
        vpp_or4(o, suf + 4 * a);
        for (int b = ba + 1; b < be; b++) vpp_or4(o, suf + 4 * (b << 5));
        vpp_or4(o, pre + 4 * e);
        return;
    }
    bend = (ba << 5) + 31 < hs->W - 1 ? (ba << 5) + 31 : hs->W - 1;
    if (a == ba << 5) {
        vpp_or4(o, pre + 4 * e);
    } else if (e == bend) {
        vpp_or4(o, suf + 4 * a);
    } else {                                        /* inside one block: read the pixels */
        int y0 = r - hs->sh_half > 0 ? r - hs->sh_half : 0;
        int y1 = r + hs->sh_half < hs->H - 1 ? r + hs->sh_half : hs->H - 1;
        for (int y = y0; y <= y1; y++)
            for (int x = a; x <= e; x++) {
                unsigned v = img[((int64_t)y * hs->W + x) * hs->C + c];
                o[v >> 6] |= (uint64_t)1 << (v & 63);
            }
    }
}

static inline void vpp_window_count(const vpp_hist_src* hs, const uint8_t* img, int c, int r, int cen,
                                    int32_t* counts) {
    int a, e;
    int y0 = r - hs->sh_half > 0 ? r - hs->sh_half : 0, y1 = r + hs->sh_half < hs->H - 1 ? r + hs->sh_half : hs->H - 1;
    vpp_window_cols(hs, cen, &a, &e);
    for (int y = y0; y <= y1; y++)
        for (int x = a; x <= e; x++) counts[img[((int64_t)y * hs->W + x) * hs->C + c]]++;
}

/* Histogram value of channel c for the windows centred on (cl, r) in L and
 * (cr, r) in R; tabs: the tables of row r, channel c (pre L, suf L, pre R,
 * suf R, 4 W words each).  All bins filled: the least frequent value. */
static inline uint8_t vpp_hist_value(const vpp_hist_src* hs, int c, int r, const uint64_t* tabs, int cl, int cr) {
    uint64_t o[4] = {0, 0, 0, 0};
    int32_t counts[256];
    const int64_t W4 = 4 * (int64_t)hs->W;
    int v, best = 0;
    vpp_window_or(hs, hs->L, c, r, tabs, tabs + W4, cl, o);
    vpp_window_or(hs, hs->R, c, r, tabs + 2 * W4, tabs + 3 * W4, cr, o);
    v = vpp_hist_pick(o);
    if (v >= 0) return (uint8_t)v;
    memset(counts, 0, sizeof counts);
    vpp_window_count(hs, hs->L, c, r, cl, counts);
    vpp_window_count(hs, hs->R, c, r, cr, counts);
    for (v = 1; v < 256; v++) if (counts[v] < counts[best]) best = v;
    return (uint8_t)best;
}

static inline void vpp_hist_row_tables(const vpp_hist_src* hs, int c, int r, uint64_t* tabs) {
    const int64_t W4 = 4 * (int64_t)hs->W;
    vpp_hist_tables(hs->L, hs->H, hs->W, hs->C, c, r, hs->sh_half, tabs, tabs + W4);
    vpp_hist_tables(hs->R, hs->H, hs->W, hs->C, c, r, hs->sh_half, tabs + 2 * W4, tabs + 3 * W4);
}

#endif
