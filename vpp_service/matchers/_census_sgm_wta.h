/* Census-SGM, winner-takes-all: the left and right WTA and the left-right check, on costs and (AVX2 build) on
 * 16-bit keys.
 * Built on _census_sgm_common.h; the driver, _census_sgm.h, includes it. */
#ifndef VPP_CENSUS_SGM_WTA_H
#define VPP_CENSUS_SGM_WTA_H

#include "_census_sgm_common.h"

/* ----------------------------------------------------------------- WTA ---- */

/* The first d < n with c[d] == v (v is among them). */
CSGM_INLINE int csgm_first_eq(const uint16_t* CSGM_RESTRICT c, int n, uint16_t v) {
    int d = 0;
#if defined(__AVX2__)
    const __m256i vv = _mm256_set1_epi16((short)v);
    for (; d + 16 <= n; d += 16) {
        unsigned m = (unsigned)_mm256_movemask_epi8(_mm256_cmpeq_epi16(_mm256_loadu_si256((const __m256i*)(c + d)), vv));
        if (m) return d + (__builtin_ctz(m) >> 1);
    }
#elif defined(__SSE2__)
    const __m128i vv = _mm_set1_epi16((short)v);
    for (; d + 8 <= n; d += 8) {
        unsigned m = (unsigned)_mm_movemask_epi8(_mm_cmpeq_epi16(_mm_loadu_si128((const __m128i*)(c + d)), vv));
        if (m) return d + (__builtin_ctz(m) >> 1);
    }
#endif
    for (; d < n; d++)
        if (c[d] == v) return d;
    return 0;
}

/* The smallest of the n >= 1 costs c[0 .. n). */
CSGM_INLINE uint16_t csgm_min16(const uint16_t* CSGM_RESTRICT c, int n) {
    uint16_t bv = 0xFFFFu;
    int d = 0;
#if defined(__AVX2__)
    __m256i vmin = _mm256_set1_epi16(-1);
    for (; d + 16 <= n; d += 16) vmin = _mm256_min_epu16(vmin, _mm256_loadu_si256((const __m256i*)(c + d)));
    {
        __m128i h = _mm_min_epu16(_mm256_castsi256_si128(vmin), _mm256_extracti128_si256(vmin, 1));
        bv = (uint16_t)_mm_cvtsi128_si32(_mm_minpos_epu16(h));
    }
#endif
    for (; d < n; d++) bv = c[d] < bv ? c[d] : bv;
    return bv;
}

/* The smallest c[d] over d < n with |d - b| > 1 (0xFFFF when there is none). */
CSGM_INLINE uint16_t csgm_min_outside(const uint16_t* CSGM_RESTRICT c, int n, int b) {
    uint16_t second = 0xFFFFu;
    int d = 0;
#if defined(__AVX2__)
    {
        /* lanes with d - (b - 1) in [0, 2] (unsigned) are left out */
        const __m256i lane = _mm256_setr_epi16(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
        const __m256i bias = _mm256_set1_epi16((int16_t)0x8000);
        const __m256i two = _mm256_set1_epi16((int16_t)(2 ^ 0x8000));
        __m256i vs = _mm256_set1_epi16(-1);
        const int blo = (b > 0 ? b - 1 : 0) >> 4, bhi = (b + 1) >> 4; /* the blocks holding b - 1 .. b + 1 */
        for (; d + 16 <= n; d += 16) {
            __m256i v = _mm256_loadu_si256((const __m256i*)(c + d));
            if ((d >> 4) == blo || (d >> 4) == bhi) {
                __m256i rel = _mm256_sub_epi16(_mm256_add_epi16(lane, _mm256_set1_epi16((int16_t)d)),
                                               _mm256_set1_epi16((int16_t)(b - 1)));
                __m256i out = _mm256_cmpgt_epi16(_mm256_xor_si256(rel, bias), two); /* rel > 2 unsigned */
                v = _mm256_or_si256(v, _mm256_andnot_si256(out, _mm256_set1_epi16(-1)));
            }
            vs = _mm256_min_epu16(vs, v);
        }
        __m128i h = _mm_min_epu16(_mm256_castsi256_si128(vs), _mm256_extracti128_si256(vs, 1));
        second = (uint16_t)_mm_cvtsi128_si32(_mm_minpos_epu16(h));
    }
#endif
    for (; d < n; d++) {
        uint16_t v = (d < b - 1 || d > b + 1) ? c[d] : (uint16_t)0xFFFFu;
        second = v < second ? v : second;
    }
    return second;
}

/* The peak-ratio term from the best cost bv and the runner-up second (have: a runner-up exists). */
CSGM_INLINE float csgm_peak_term(unsigned bv, unsigned second, int have, double peak) {
    if (!have || second == 0) return 0.0f;
    const double m = (1.0 - (double)bv / (double)second) / peak;
    return (float)(m < 1.0 ? m : 1.0);
}

/* Left WTA of one pixel over its n valid disparities (lowest d on ties), uniqueness, parabola.  In the left
 * band (n < D) a minimum at the largest existing d = n - 1 is rejected: the match may lie beyond the image.
 * With conf (not NULL; callers pass a constant NULL to leave it out), also the pixel's peak-ratio term (see
 * csgm_conf_row) into *conf and its best d (before any rejection) into *best. */
CSGM_INLINE float csgm_wta_pixel(const uint16_t* CSGM_RESTRICT c, int n, int D, double uniqueness, int subpixel,
                                 double peak, float* CSGM_RESTRICT conf, uint16_t* CSGM_RESTRICT best) {
    const uint16_t bv = csgm_min16(c, n);
    const int b = csgm_first_eq(c, n, bv);
    const int band = n < D && b == n - 1;
    const int have = b >= 2 || b + 2 <= n - 1; /* some d with |d - best| > 1 */
    const uint16_t second = have && (conf || !band) ? csgm_min_outside(c, n, b) : (uint16_t)0xFFFFu;
    if (conf) {
        *best = (uint16_t)b;
        *conf = csgm_peak_term(bv, second, have, peak);
    }
    if (band) return NAN;
    if (have && !((double)bv < uniqueness * (double)second)) return NAN;
    if (subpixel && b > 0 && b < n - 1) {
        int c0 = c[b - 1], c2 = c[b + 1];
        int denom = c0 - 2 * (int)bv + c2;
        if (denom > 0) return (float)((double)b + (double)(c0 - c2) / (2.0 * (double)denom));
    }
    return (float)b;
}

static void csgm_wta_row(const uint16_t* CSGM_RESTRICT S, float* CSGM_RESTRICT out, int W, int D,
                         double uniqueness, int subpixel) {
    for (int x = 0; x < W; x++) {
        const int n = x + 1 < D ? x + 1 : D;
        out[x] = csgm_wta_pixel(S + (ptrdiff_t)x * D, n, D, uniqueness, subpixel, 0.0, NULL, NULL);
    }
}

/* Right WTA of one row: out[xr] = argmin_d S[xr + d][d] (lowest d on ties), as a running minimum along
 * the diagonals while x ascends.  rbc, rbd: W scratch entries. */
/* Right WTA, one left pixel x (costs c, n valid): bc[d], bd[d] (right pixel x - d, reversed) keep the lowest
 * cost and its d; x ascends, so the strict < keeps the lowest d on ties. */
CSGM_INLINE void csgm_right_pixel(const uint16_t* CSGM_RESTRICT c, int n, uint16_t* CSGM_RESTRICT bc,
                                  uint16_t* CSGM_RESTRICT bd) {
    int d = 0;
#if defined(__AVX2__)
    {
        const __m256i lane = _mm256_setr_epi16(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
        const __m256i bias = _mm256_set1_epi16((int16_t)0x8000);
        for (; d + 16 <= n; d += 16) {
            const __m256i v = _mm256_loadu_si256((const __m256i*)(c + d));
            const __m256i o = _mm256_loadu_si256((const __m256i*)(bc + d));
            const __m256i lt = _mm256_cmpgt_epi16(_mm256_xor_si256(o, bias), _mm256_xor_si256(v, bias));
            const __m256i dv = _mm256_add_epi16(lane, _mm256_set1_epi16((int16_t)d));
            _mm256_storeu_si256((__m256i*)(bd + d),
                                _mm256_blendv_epi8(_mm256_loadu_si256((const __m256i*)(bd + d)), dv, lt));
            _mm256_storeu_si256((__m256i*)(bc + d), _mm256_min_epu16(v, o));
        }
    }
#endif
    for (; d < n; d++) {
        const uint16_t v = c[d], o = bc[d];
        bd[d] = v < o ? (uint16_t)d : bd[d];
        bc[d] = v < o ? v : o;
    }
}

static void csgm_right_row(const uint16_t* CSGM_RESTRICT S, float* CSGM_RESTRICT out, int W, int D,
                           uint16_t* CSGM_RESTRICT rbc, uint16_t* CSGM_RESTRICT rbd) {
    for (int i = 0; i < W; i++) {
        rbc[i] = 0xFFFFu;
        rbd[i] = 0;
    }
    for (int x = 0; x < W; x++) {
        const int n = x + 1 < D ? x + 1 : D;
        csgm_right_pixel(S + (ptrdiff_t)x * D, n, rbc + (W - 1 - x), rbd + (W - 1 - x));
    }
    for (int xr = 0; xr < W; xr++) out[xr] = (float)rbd[W - 1 - xr];
}

static void csgm_lr_row(const float* CSGM_RESTRICT dl, const float* CSGM_RESTRICT dr, float* CSGM_RESTRICT out,
                        int W, double tol) {
    int x = 0;
#if defined(__AVX2__)
    if (W < (1 << 21)) {
        /* 8 pixels at once, branch-free.  |d| < 2^21: floor(d + 0.5f) is exact in float and its int fits; a
         * larger |d| puts x - floor(d + 0.5) outside 0 .. W - 1 anyway.  The tolerance test in double. */
        const __m256 half = _mm256_set1_ps(0.5f), big = _mm256_set1_ps(2097152.0f);
        const __m256 absmask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7FFFFFFF));
        const __m256d absmask_d = _mm256_castsi256_pd(_mm256_set1_epi64x(0x7FFFFFFFFFFFFFFFLL));
        const __m256d vtol = _mm256_set1_pd(tol);
        const __m256 nan = _mm256_set1_ps(NAN);
        const __m256i wv = _mm256_set1_epi32(W);
        __m256i xv = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
        for (; x + 8 <= W; x += 8, xv = _mm256_add_epi32(xv, _mm256_set1_epi32(8))) {
            const __m256 d = _mm256_loadu_ps(dl + x);
            const __m256 ok = _mm256_cmp_ps(_mm256_and_ps(d, absmask), big, _CMP_LT_OQ); /* also: not NaN */
            const __m256 rd = _mm256_floor_ps(_mm256_and_ps(_mm256_add_ps(d, half), ok));
            const __m256i xr = _mm256_sub_epi32(xv, _mm256_cvttps_epi32(rd));
            const __m256i in = _mm256_and_si256(_mm256_castps_si256(ok),
                                                _mm256_andnot_si256(_mm256_cmpgt_epi32(_mm256_setzero_si256(), xr),
                                                                    _mm256_cmpgt_epi32(wv, xr)));
            const __m256 r = _mm256_mask_i32gather_ps(nan, dr, xr, _mm256_castsi256_ps(in), 4);
            const __m256d lo = _mm256_and_pd(
                _mm256_sub_pd(_mm256_cvtps_pd(_mm256_castps256_ps128(d)), _mm256_cvtps_pd(_mm256_castps256_ps128(r))),
                absmask_d);
            const __m256d hi = _mm256_and_pd(_mm256_sub_pd(_mm256_cvtps_pd(_mm256_extractf128_ps(d, 1)),
                                                           _mm256_cvtps_pd(_mm256_extractf128_ps(r, 1))),
                                             absmask_d);
            /* |d - r| <= tol (false for a NaN r; a NaN d was left out above), the two halves' 64-bit masks
             * narrowed to 32 bits */
            const __m256i sel = _mm256_setr_epi32(0, 2, 4, 6, 0, 2, 4, 6);
            const __m128i plo = _mm256_castsi256_si128(
                _mm256_permutevar8x32_epi32(_mm256_castpd_si256(_mm256_cmp_pd(lo, vtol, _CMP_LE_OQ)), sel));
            const __m128i phi = _mm256_castsi256_si128(
                _mm256_permutevar8x32_epi32(_mm256_castpd_si256(_mm256_cmp_pd(hi, vtol, _CMP_LE_OQ)), sel));
            const __m256 pass = _mm256_castsi256_ps(_mm256_inserti128_si256(_mm256_castsi128_si256(plo), phi, 1));
            _mm256_storeu_ps(out + x, _mm256_blendv_ps(nan, d, _mm256_and_ps(pass, _mm256_castsi256_ps(in))));
        }
    }
#endif
    for (; x < W; x++) {
        float d = dl[x];
        float r = NAN;
        if (!isnan(d)) {
            int xr = x - (int)floor((double)d + 0.5);
            if (xr >= 0 && xr < W && !isnan(dr[xr]) && fabs((double)d - (double)dr[xr]) <= tol) r = d;
        }
        out[x] = r;
    }
}

/* --------------------------------------------------------- confidence ----
 * Computed only when asked (csgm_finish_row with a confidence map), the disparity unchanged.  Per pixel the
 * left WTA (csgm_wta_pixel, csgm_wta_keys) gives, from the costs it already has, the best disparity b
 * (lowest d on ties, over the n valid ones) and the peak-ratio term of its cost and the runner-up outside
 * b - 1 .. b + 1, min(1, (1 - best / second) / peak) (0 without a runner-up or with second == 0); the row's
 * right WTA then gives the left-right term max(0, 1 - |b - d_R(x - b)| / span); the confidence is their
 * product, in [0, 1]. */

/* The confidence of a row in place: conf[x] (the peak-ratio term) times the left-right term of the best d
 * b[x] against the row's right WTA r (integer disparities). */
static void csgm_conf_row(const uint16_t* CSGM_RESTRICT b, const float* CSGM_RESTRICT r, float* CSGM_RESTRICT conf,
                          int W, double span) {
    for (int x = 0; x < W; x++) {
        const double diff = fabs((double)b[x] - (double)r[x - b[x]]);
        const double lr = 1.0 - diff / span;
        conf[x] = lr > 0.0 ? (float)((double)conf[x] * lr) : 0.0f;
    }
}

#if defined(__AVX2__)
/* ------------------------------------------------- WTA on keys (p->packed) --
 * With narrow partial sums a pixel's full sum S[d] is at most 2 * 255 = 510, so for D <= 128 the 16-bit
 * key (S[d] << 7) | d orders the disparities by cost, then by d: the smallest key is the lowest-cost
 * disparity with the lowest d, as csgm_wta_pixel and csgm_right_pixel choose, and carries its cost.  Keys
 * of absent disparities (d >= n, d >= D) are 0xFFFF, above every real key (<= 510 * 128 + 127). */

/* The keys of pixel x (n valid disparities) from its two passes' uint8 partial sums ax, bx (D each) into
 * k = t->keys + 16; k[d] for D <= d < 128 and the padding stay 0xFFFF. */
CSGM_INLINE void csgm_pack_px(const uint8_t* CSGM_RESTRICT ax, const uint8_t* CSGM_RESTRICT bx,
                              uint16_t* CSGM_RESTRICT k, int n, int D) {
    const __m256i last = _mm256_set1_epi16((int16_t)(n - 1)), sixteen = _mm256_set1_epi16(16);
    __m256i dv = _mm256_setr_epi16(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    int d = 0;
    for (; d + 16 <= D; d += 16) {
        const __m256i s = _mm256_add_epi16(_mm256_cvtepu8_epi16(_mm_loadu_si128((const __m128i*)(ax + d))),
                                           _mm256_cvtepu8_epi16(_mm_loadu_si128((const __m128i*)(bx + d))));
        const __m256i key = _mm256_or_si256(_mm256_slli_epi16(s, 7), dv);
        _mm256_store_si256((__m256i*)(k + d), _mm256_or_si256(key, _mm256_cmpgt_epi16(dv, last)));
        dv = _mm256_add_epi16(dv, sixteen);
    }
    for (; d < D; d++) k[d] = d < n ? (uint16_t)(((ax[d] + bx[d]) << 7) | d) : (uint16_t)0xFFFFu;
}

/* csgm_wta_pixel on the keys k of a pixel (n valid).  One pass keeps, per lane (d mod 16), the smallest
 * and second-smallest key over the 8 blocks; the smallest over the lanes gives b and its cost.  The
 * runner-up outside b - 1 .. b + 1 is each lane's smallest key, or its second where the smallest is one
 * of those three (keys are distinct, so equality identifies it). */
CSGM_INLINE float csgm_wta_keys(const uint16_t* CSGM_RESTRICT k, int n, int D, double uniqueness, int subpixel,
                                double peak, float* CSGM_RESTRICT conf, uint16_t* CSGM_RESTRICT bestd) {
    const __m256i lane = _mm256_setr_epi16(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    __m256i lo[4], hi[4];
    for (int i = 0; i < 4; i++) {
        const __m256i a = _mm256_load_si256((const __m256i*)(k + 32 * i));
        const __m256i c = _mm256_load_si256((const __m256i*)(k + 32 * i + 16));
        lo[i] = _mm256_min_epu16(a, c);
        hi[i] = _mm256_max_epu16(a, c);
    }
    for (int step = 1; step < 4; step *= 2) /* pairs of (smallest, second) per lane, as a tree */
        for (int i = 0; i + step < 4; i += 2 * step) {
            const __m256i m = _mm256_min_epu16(lo[i], lo[i + step]);
            hi[i] = _mm256_min_epu16(_mm256_max_epu16(lo[i], lo[i + step]), _mm256_min_epu16(hi[i], hi[i + step]));
            lo[i] = m;
        }
    const unsigned best = csgm_hmin16u(lo[0]);
    const int b = (int)(best & 127u);
    const unsigned bv = best >> 7;
    const int band = n < D && b == n - 1;
    const int have = b >= 2 || b + 2 <= n - 1; /* some d with |d - best| > 1 */
    unsigned second = 0xFFFFu;
    if (have && (conf || !band)) {
        const int base = (b - 1) & ~15, r = (b - 1) & 15; /* b - 1 .. b + 1: lanes r .. r + 2 (mod 16) */
        const __m256i rv = _mm256_set1_epi16((int16_t)r);
        const __m256i rel = _mm256_and_si256(_mm256_sub_epi16(lane, rv), _mm256_set1_epi16(15));
        const __m256i three = _mm256_cmpeq_epi16(_mm256_min_epu16(rel, _mm256_set1_epi16(2)), rel);
        const __m256i w = _mm256_blendv_epi8(_mm256_loadu_si256((const __m256i*)(k + base)),
                                             _mm256_loadu_si256((const __m256i*)(k + base + 16)),
                                             _mm256_cmpgt_epi16(rv, lane)); /* lanes < r: the next block */
        const __m256i use2 = _mm256_and_si256(three, _mm256_cmpeq_epi16(lo[0], w));
        second = csgm_hmin16u(_mm256_blendv_epi8(lo[0], hi[0], use2)) >> 7;
    }
    if (conf) { /* csgm_wta_pixel's */
        *bestd = (uint16_t)b;
        *conf = csgm_peak_term(bv, second, have, peak);
    }
    if (band) return NAN;
    if (have && !((double)bv < uniqueness * (double)second)) return NAN;
    if (subpixel && b > 0 && b < n - 1) {
        int c0 = k[b - 1] >> 7, c2 = k[b + 1] >> 7;
        int denom = c0 - 2 * (int)bv + c2;
        if (denom > 0) return (float)((double)b + (double)(c0 - c2) / (2.0 * (double)denom));
    }
    return (float)b;
}

/* Right WTA update of one left pixel on its keys k (n valid): bk[d] (right pixel x - d, reversed) keeps the
 * smallest key.  Whole blocks: the keys past n are 0xFFFF and bk has 16 entries of slack. */
CSGM_INLINE void csgm_right_keys(const uint16_t* CSGM_RESTRICT k, int n, uint16_t* CSGM_RESTRICT bk) {
    for (int d = 0; d < n; d += 16)
        _mm256_storeu_si256((__m256i*)(bk + d), _mm256_min_epu16(_mm256_loadu_si256((const __m256i*)(bk + d)),
                                                                 _mm256_load_si256((const __m256i*)(k + d))));
}
#endif

#endif
