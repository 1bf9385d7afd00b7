/* Census-SGM kernels in C (included by _census_sgm.pyx; compiled twice: portable and x86-64-v3).
 *
 * Plain loops written so that GCC/Clang vectorise them (-O3): int16 path costs,
 * uint16 sums, branch-free selects; AVX2 intrinsics in the x86-64-v3 build.  The per-call driver csgm_sgm runs one OpenMP
 * parallel region: the forward pass (4 paths: left->right and the three from the
 * row above) and the backward pass (the 4 mirrored paths) run on two threads at
 * once; whichever pass finishes a row second adds the two partial sums and runs
 * the row's left and right winner-takes-all and left-right check; after one
 * barrier all threads run the 3x3 median on row blocks.  With one thread the
 * forward pass runs first, then the backward pass finishes every row.
 *
 * Valid disparities of column x are d <= min(x, D - 1) ("band"): path costs of
 * the others hold CSGM_SENT, which never wins a minimum.
 *
 * Partial sums (the 4 or 2 paths of one pass) are uint8 when they provably fit ("narrow", see
 * csgm_narrow: the Hamming costs computed in the passes and small penalties), else uint16; the two
 * passes' sums are added in uint16 for the WTA.  uint8 halves the bytes the passes write and the row
 * finisher reads, which bounds the two-thread speed.  Under the same bound the AVX2 build keeps the
 * path costs themselves as uint8 too (csgm_pass_row8: 8 paths, D a multiple of 16).  A full sum is then at
 * most 510, so with D <= 128 the row finisher runs both winner-takes-all on 16-bit keys (sum << 7) | d, whose
 * minimum is the disparity and its cost at once (csgm_wta_keys, csgm_right_keys).
 *
 * Each pass aggregates a row into its own scratch row (in cache whichever way x runs) and copies it to
 * its partial-sum volume only when it reaches the row first; the pass that comes second finishes the row
 * (sum, WTAs, left-right check, border step, short gaps) from its scratch row.
 */
#ifndef VPP_CENSUS_SGM_H
#define VPP_CENSUS_SGM_H

#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "_gaps.h"
#include "_omp_team.h"
#ifdef _OPENMP
#include <omp.h>
#endif
#if defined(__AVX__) || defined(__SSE2__)
#include <immintrin.h>
#endif

#define CSGM_SENT 16383 /* > any path cost (<= 4095 + 4095); + P1 (<= 4095) fits int16 */
#define CSGM_NOCOST 65535u /* aggregated cost of an invalid (x < d) entry */

#if defined(__GNUC__)
#define CSGM_RESTRICT __restrict__
#define CSGM_INLINE static inline __attribute__((always_inline))
#else
#define CSGM_RESTRICT
#define CSGM_INLINE static inline
#endif

static int csgm_build_avx2(void) {
#ifdef __AVX2__
    return 1;
#else
    return 0;
#endif
}

/* ------------------------------------------------------------------ census */

/* Rows [y0, y1) of the 5x5 census of img (H x W) using pad, the image replicated by 2 on every side
 * ((H + 4) x (W + 4), filled by csgm_pad_rows).  b0..b2: three scratch rows of W bytes. */
static void csgm_census_rows(const uint8_t* CSGM_RESTRICT pad, int H, int W, uint32_t* CSGM_RESTRICT out,
                             int y0, int y1, uint8_t* CSGM_RESTRICT b0, uint8_t* CSGM_RESTRICT b1,
                             uint8_t* CSGM_RESTRICT b2) {
    const ptrdiff_t P = (ptrdiff_t)W + 4;
    (void)H;
    for (int y = y0; y < y1; y++) {
        /* q[k]: the window offset k (row-major, centre skipped) of pixel 0; c: the centre */
        const uint8_t* r = pad + (ptrdiff_t)y * P;
        const uint8_t* CSGM_RESTRICT c = r + 2 * P + 2;
        const uint8_t *q0 = r, *q1 = r + 1, *q2 = r + 2, *q3 = r + 3, *q4 = r + 4;
        const uint8_t *q5 = r + P, *q6 = q5 + 1, *q7 = q5 + 2, *q8 = q5 + 3, *q9 = q5 + 4;
        const uint8_t *q10 = r + 2 * P, *q11 = q10 + 1, *q12 = q10 + 3, *q13 = q10 + 4;
        const uint8_t *q14 = r + 3 * P, *q15 = q14 + 1, *q16 = q14 + 2, *q17 = q14 + 3, *q18 = q14 + 4;
        const uint8_t *q19 = r + 4 * P, *q20 = q19 + 1, *q21 = q19 + 2, *q22 = q19 + 3, *q23 = q19 + 4;
        for (ptrdiff_t x = 0; x < W; x++) {
            const uint8_t v = c[x];
            b0[x] = (uint8_t)(((q0[x] < v) << 7) | ((q1[x] < v) << 6) | ((q2[x] < v) << 5) | ((q3[x] < v) << 4) |
                              ((q4[x] < v) << 3) | ((q5[x] < v) << 2) | ((q6[x] < v) << 1) | (q7[x] < v));
            b1[x] = (uint8_t)(((q8[x] < v) << 7) | ((q9[x] < v) << 6) | ((q10[x] < v) << 5) | ((q11[x] < v) << 4) |
                              ((q12[x] < v) << 3) | ((q13[x] < v) << 2) | ((q14[x] < v) << 1) | (q15[x] < v));
            b2[x] = (uint8_t)(((q16[x] < v) << 7) | ((q17[x] < v) << 6) | ((q18[x] < v) << 5) |
                              ((q19[x] < v) << 4) | ((q20[x] < v) << 3) | ((q21[x] < v) << 2) | ((q22[x] < v) << 1) |
                              (q23[x] < v));
        }
        uint32_t* CSGM_RESTRICT o = out + (ptrdiff_t)y * W;
        for (ptrdiff_t x = 0; x < W; x++)
            o[x] = ((uint32_t)b0[x] << 16) | ((uint32_t)b1[x] << 8) | (uint32_t)b2[x];
    }
}

/* Padded rows [y0, y1) of the (H + 4) x (W + 4) edge-replicated copy of img. */
static void csgm_pad_rows(const uint8_t* CSGM_RESTRICT img, int H, int W, uint8_t* CSGM_RESTRICT pad, int y0,
                          int y1) {
    const ptrdiff_t P = (ptrdiff_t)W + 4;
    for (int py = y0; py < y1; py++) {
        int y = py - 2;
        y = y < 0 ? 0 : (y > H - 1 ? H - 1 : y);
        const uint8_t* s = img + (ptrdiff_t)y * W;
        uint8_t* d = pad + (ptrdiff_t)py * P;
        d[0] = d[1] = s[0];
        memcpy(d + 2, s, (size_t)W);
        d[W + 2] = d[W + 3] = s[W - 1];
    }
}

/* ----------------------------------------------------------------- hamming */

CSGM_INLINE uint16_t csgm_popcount24(uint32_t v) {
    v = v - ((v >> 1) & 0x55555555u);
    v = (v & 0x33333333u) + ((v >> 2) & 0x33333333u);
    v = (v + (v >> 4)) & 0x0F0F0F0Fu;
    v = v + (v >> 8);
    v = v + (v >> 16);
    return (uint16_t)(v & 0x3F);
}

/* One pixel of a Hamming row: p[d] = popcount(a ^ q[d]) for d < n, invalid_cost for n <= d < D. */
CSGM_INLINE void csgm_hamming_px(uint32_t a, const uint32_t* CSGM_RESTRICT q, uint16_t* CSGM_RESTRICT p, int n,
                                 int D, uint16_t invalid_cost) {
    int d = 0;
#if defined(__AVX2__)
    {
        /* popcount of 16 codes: nibble counts by table lookup, summed per 32-bit lane, packed to 16 bits */
        const __m256i nib = _mm256_setr_epi8(0, 1, 1, 2, 1, 2, 2, 3, 1, 2, 2, 3, 2, 3, 3, 4, 0, 1, 1, 2, 1, 2, 2, 3,
                                             1, 2, 2, 3, 2, 3, 3, 4);
        const __m256i low = _mm256_set1_epi8(0x0F), ones = _mm256_set1_epi8(1);
        const __m256i va = _mm256_set1_epi32((int)a);
        for (; d + 16 <= n; d += 16) {
            __m256i u = _mm256_xor_si256(_mm256_loadu_si256((const __m256i*)(q + d)), va);
            __m256i v = _mm256_xor_si256(_mm256_loadu_si256((const __m256i*)(q + d + 8)), va);
            u = _mm256_add_epi8(_mm256_shuffle_epi8(nib, _mm256_and_si256(u, low)),
                                _mm256_shuffle_epi8(nib, _mm256_and_si256(_mm256_srli_epi16(u, 4), low)));
            v = _mm256_add_epi8(_mm256_shuffle_epi8(nib, _mm256_and_si256(v, low)),
                                _mm256_shuffle_epi8(nib, _mm256_and_si256(_mm256_srli_epi16(v, 4), low)));
            u = _mm256_maddubs_epi16(u, ones); /* byte pairs -> 16 bits */
            v = _mm256_maddubs_epi16(v, ones);
            __m256i h = _mm256_hadd_epi16(u, v); /* 32-bit lanes, in-lane order u0-3 v0-3 | u4-7 v4-7 */
            _mm256_storeu_si256((__m256i*)(p + d), _mm256_permute4x64_epi64(h, 0xD8));
        }
    }
#endif
    for (; d < n; d++) p[d] = csgm_popcount24(a ^ q[d]);
    for (d = n; d < D; d++) p[d] = invalid_cost;
}

/* Row y of the Hamming volume: out[x][d] = popcount(cl[x] ^ cr[x - d]) for d <= x, invalid_cost above.
 * rev: W scratch entries (cr reversed, so the d loop reads forwards). */
static void csgm_hamming_row(const uint32_t* CSGM_RESTRICT cl, const uint32_t* CSGM_RESTRICT cr,
                             uint32_t* CSGM_RESTRICT rev, uint16_t* CSGM_RESTRICT out, int W, int D,
                             uint16_t invalid_cost) {
    for (int x = 0; x < W; x++) rev[x] = cr[W - 1 - x];
    for (int x = 0; x < W; x++) {
        const int n = x + 1 < D ? x + 1 : D;
        /* rev + (W - 1 - x): q[d] == cr[x - d] */
        csgm_hamming_px(cl[x], rev + (W - 1 - x), out + (ptrdiff_t)x * D, n, D, invalid_cost);
    }
}

/* --------------------------------------------------------------------- SGM */

/* One pixel of the 4 paths of a pass (prev[k], cur[k]: element 0 of path-cost buffers with a sentinel at
 * -1 and D; a path's first pixel reads a row of zeros with pm = 0, which gives L = C):
 * L_k(d) = C(d) + min(L'_k(d), L'_k(d-1) + P1, L'_k(d+1) + P1, pm_k + P2_k) - pm_k over the n valid d,
 * the sentinel above; acc = sum_k L_k.  Returns min_d L_k in m[k]. */
CSGM_INLINE void csgm_step4(const uint16_t* CSGM_RESTRICT C, const int16_t* CSGM_RESTRICT p0,
                            const int16_t* CSGM_RESTRICT p1, const int16_t* CSGM_RESTRICT p2,
                            const int16_t* CSGM_RESTRICT p3, int16_t* CSGM_RESTRICT c0, int16_t* CSGM_RESTRICT c1,
                            int16_t* CSGM_RESTRICT c2, int16_t* CSGM_RESTRICT c3, const int16_t* pm,
                            const int16_t* P2, int16_t* m, void* CSGM_RESTRICT acc, int n, int D, int16_t P1,
                            int narrow) {
    uint8_t* CSGM_RESTRICT a8 = (uint8_t*)acc;
    uint16_t* CSGM_RESTRICT a16 = (uint16_t*)acc;
    const int16_t pm0 = pm[0], pm1 = pm[1], pm2 = pm[2], pm3 = pm[3];
    const int16_t j0 = (int16_t)(pm0 + P2[0]), j1 = (int16_t)(pm1 + P2[1]), j2 = (int16_t)(pm2 + P2[2]),
                  j3 = (int16_t)(pm3 + P2[3]);
    int16_t m0 = CSGM_SENT, m1 = CSGM_SENT, m2 = CSGM_SENT, m3 = CSGM_SENT;
#define CSGM_PATH(p, c, pmk, jk, mk, Lk)                                  \
    int16_t Lk;                                                           \
    {                                                                     \
        int16_t v = p[d], a = p[d - 1], b = p[d + 1];                     \
        a = b < a ? b : a;                                                \
        a = (int16_t)(a + P1);                                            \
        v = a < v ? a : v;                                                \
        v = jk < v ? jk : v;                                              \
        Lk = (int16_t)(cd + v - pmk);                                     \
        c[d] = Lk;                                                        \
        mk = Lk < mk ? Lk : mk;                                           \
    }
    for (int d = 0; d < n; d++) {
        const int16_t cd = (int16_t)C[d];
        CSGM_PATH(p0, c0, pm0, j0, m0, L0)
        CSGM_PATH(p1, c1, pm1, j1, m1, L1)
        CSGM_PATH(p2, c2, pm2, j2, m2, L2)
        CSGM_PATH(p3, c3, pm3, j3, m3, L3)
        if (narrow)
            a8[d] = (uint8_t)(L0 + L1 + L2 + L3);
        else
            a16[d] = (uint16_t)(L0 + L1 + L2 + L3);
    }
    for (int d = n; d < D; d++) c0[d] = c1[d] = c2[d] = c3[d] = CSGM_SENT;
    m[0] = m0;
    m[1] = m1;
    m[2] = m2;
    m[3] = m3;
}

/* The same for the 2 paths of a pass with 4 paths in all (horizontal and vertical). */
CSGM_INLINE void csgm_step2(const uint16_t* CSGM_RESTRICT C, const int16_t* CSGM_RESTRICT p0,
                            const int16_t* CSGM_RESTRICT p1, int16_t* CSGM_RESTRICT c0, int16_t* CSGM_RESTRICT c1,
                            const int16_t* pm, const int16_t* P2, int16_t* m, void* CSGM_RESTRICT acc, int n,
                            int D, int16_t P1, int narrow) {
    uint8_t* CSGM_RESTRICT a8 = (uint8_t*)acc;
    uint16_t* CSGM_RESTRICT a16 = (uint16_t*)acc;
    const int16_t pm0 = pm[0], pm1 = pm[1];
    const int16_t j0 = (int16_t)(pm0 + P2[0]), j1 = (int16_t)(pm1 + P2[1]);
    int16_t m0 = CSGM_SENT, m1 = CSGM_SENT;
    for (int d = 0; d < n; d++) {
        const int16_t cd = (int16_t)C[d];
        CSGM_PATH(p0, c0, pm0, j0, m0, L0)
        CSGM_PATH(p1, c1, pm1, j1, m1, L1)
        if (narrow)
            a8[d] = (uint8_t)(L0 + L1);
        else
            a16[d] = (uint16_t)(L0 + L1);
    }
#undef CSGM_PATH
    for (int d = n; d < D; d++) c0[d] = c1[d] = CSGM_SENT;
    m[0] = m0;
    m[1] = m1;
}

CSGM_INLINE int csgm_absdiff(int a, int b) { return a > b ? a - b : b - a; }

#if defined(__AVX2__)
CSGM_INLINE int16_t csgm_hmin16(__m256i v) {
    /* path costs are >= 0, so the unsigned minpos gives the signed minimum */
    __m128i h = _mm_min_epi16(_mm256_castsi256_si128(v), _mm256_extracti128_si256(v, 1));
    return (int16_t)_mm_cvtsi128_si32(_mm_minpos_epu16(h));
}

/* The smallest of 16 uint16 lanes. */
CSGM_INLINE unsigned csgm_hmin16u(__m256i v) {
    __m128i h = _mm_min_epu16(_mm256_castsi256_si128(v), _mm256_extracti128_si256(v, 1));
    return (unsigned)(uint16_t)_mm_cvtsi128_si32(_mm_minpos_epu16(h));
}

/* csgm_step4 for D a multiple of 16 (the same integers, 16 disparities per instruction): lanes d >= n get
 * the sentinel before they are stored or enter the minimum; acc there is left undefined (never read). */
CSGM_INLINE void csgm_step4_avx2(const uint16_t* CSGM_RESTRICT C, const int16_t* CSGM_RESTRICT p0,
                                 const int16_t* CSGM_RESTRICT p1, const int16_t* CSGM_RESTRICT p2,
                                 const int16_t* CSGM_RESTRICT p3, int16_t* CSGM_RESTRICT c0,
                                 int16_t* CSGM_RESTRICT c1, int16_t* CSGM_RESTRICT c2, int16_t* CSGM_RESTRICT c3,
                                 const int16_t* pm, const int16_t* P2, int16_t* m, void* CSGM_RESTRICT acc,
                                 int n, int D, int16_t P1, int narrow) {
    const __m256i vp1 = _mm256_set1_epi16(P1);
    const __m256i pm0 = _mm256_set1_epi16(pm[0]), pm1 = _mm256_set1_epi16(pm[1]);
    const __m256i pm2 = _mm256_set1_epi16(pm[2]), pm3 = _mm256_set1_epi16(pm[3]);
    const __m256i j0 = _mm256_set1_epi16((int16_t)(pm[0] + P2[0])), j1 = _mm256_set1_epi16((int16_t)(pm[1] + P2[1]));
    const __m256i j2 = _mm256_set1_epi16((int16_t)(pm[2] + P2[2])), j3 = _mm256_set1_epi16((int16_t)(pm[3] + P2[3]));
    const __m256i sent = _mm256_set1_epi16(CSGM_SENT);
    __m256i m0 = sent, m1 = m0, m2 = m0, m3 = m0;
#define CSGM_LD(p) _mm256_loadu_si256((const __m256i*)(p))
#define CSGM_VPATH(p, c, pmk, jk, mk, Lk)                                                              \
    __m256i Lk = _mm256_add_epi16(_mm256_min_epi16(CSGM_LD(p + d - 1), CSGM_LD(p + d + 1)), vp1);      \
    Lk = _mm256_min_epi16(_mm256_min_epi16(Lk, CSGM_LD(p + d)), jk);                                   \
    Lk = _mm256_add_epi16(Lk, _mm256_sub_epi16(cd, pmk));                                              \
    _mm256_storeu_si256((__m256i*)(c + d), Lk);                                                        \
    mk = _mm256_min_epi16(mk, Lk);
/* narrow: packus saturates, exact on the valid lanes (<= 255); lanes d >= n are never read */
#define CSGM_STORE_ACC(v)                                                                              \
    {                                                                                                  \
        const __m256i s_ = (v);                                                                        \
        if (narrow)                                                                                    \
            _mm_storeu_si128((__m128i*)((uint8_t*)acc + d),                                            \
                             _mm_packus_epi16(_mm256_castsi256_si128(s_),                              \
                                              _mm256_extracti128_si256(s_, 1)));                       \
        else                                                                                           \
            _mm256_storeu_si256((__m256i*)((uint16_t*)acc + d), s_);                                   \
    }
    int d = 0;
    for (; d + 16 <= n; d += 16) {
        const __m256i cd = CSGM_LD(C + d);
        CSGM_VPATH(p0, c0, pm0, j0, m0, L0)
        CSGM_VPATH(p1, c1, pm1, j1, m1, L1)
        CSGM_VPATH(p2, c2, pm2, j2, m2, L2)
        CSGM_VPATH(p3, c3, pm3, j3, m3, L3)
        CSGM_STORE_ACC(_mm256_add_epi16(_mm256_add_epi16(L0, L1), _mm256_add_epi16(L2, L3)));
    }
#undef CSGM_VPATH
    if (d < n) { /* the last, partial block of the left band: lanes d >= n are absent */
        const __m256i lane = _mm256_setr_epi16(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
        const __m256i keep = _mm256_cmpgt_epi16(_mm256_set1_epi16((int16_t)(n - d)), lane);
        const __m256i cd = CSGM_LD(C + d);
#define CSGM_VPATH(p, c, pmk, jk, mk, Lk)                                                              \
    __m256i Lk = _mm256_add_epi16(_mm256_min_epi16(CSGM_LD(p + d - 1), CSGM_LD(p + d + 1)), vp1);      \
    Lk = _mm256_min_epi16(_mm256_min_epi16(Lk, CSGM_LD(p + d)), jk);                                   \
    Lk = _mm256_blendv_epi8(sent, _mm256_add_epi16(Lk, _mm256_sub_epi16(cd, pmk)), keep);              \
    _mm256_storeu_si256((__m256i*)(c + d), Lk);                                                        \
    mk = _mm256_min_epi16(mk, Lk);
        CSGM_VPATH(p0, c0, pm0, j0, m0, L0)
        CSGM_VPATH(p1, c1, pm1, j1, m1, L1)
        CSGM_VPATH(p2, c2, pm2, j2, m2, L2)
        CSGM_VPATH(p3, c3, pm3, j3, m3, L3)
#undef CSGM_VPATH
        CSGM_STORE_ACC(_mm256_add_epi16(_mm256_add_epi16(L0, L1), _mm256_add_epi16(L2, L3)));
        d += 16;
    }
    for (; d < D; d += 16) {
        _mm256_storeu_si256((__m256i*)(c0 + d), sent);
        _mm256_storeu_si256((__m256i*)(c1 + d), sent);
        _mm256_storeu_si256((__m256i*)(c2 + d), sent);
        _mm256_storeu_si256((__m256i*)(c3 + d), sent);
    }
#undef CSGM_LD
#undef CSGM_STORE_ACC
    m[0] = csgm_hmin16(m0);
    m[1] = csgm_hmin16(m1);
    m[2] = csgm_hmin16(m2);
    m[3] = csgm_hmin16(m3);
}
#endif

typedef struct {
    int H, W, D, paths, P1;
    const int16_t* p2lut; /* 256 entries */
    double uniqueness;
    int subpixel, lr_check, median;
    double tolerance;
    const uint32_t* cl; /* census codes (H x W): with cost == NULL the passes compute each cost row from them */
    const uint32_t* cr;
    int narrow; /* partial sums are uint8 (set by csgm_sgm from csgm_narrow) */
    int narrow8; /* AVX2 build, 8 paths, D % 16 == 0 and narrow: the path costs are uint8 too (csgm_pass_row8) */
    int packed;  /* AVX2 build, narrow and D <= 128: the row finisher's WTAs run on keys (csgm_pack_px) */
    int border_margin; /* after the left-right check: border.reject_border_matches (0 = off) */
    int gap_size;      /* then holes.fill_short_gaps (0 = off) with gap_step */
    double gap_step;
} csgm_params;

/* Whether the partial sums of a pass fit uint8: the costs are the Hamming costs the passes compute (<= 24,
 * cost volume == NULL) and (paths / 2) * (24 + max P2) <= 255 with every P2 >= 0.  A path cost is
 * L = C + min(L'(d), L'(d +- 1) + P1, pm + P2) - pm with pm = min L' <= L'(d), so C <= L <= C + P2 (the
 * first pixel of a path has L = C); a pass sums paths / 2 of them.  Guided stereo (a modulated cost volume)
 * and large penalties keep uint16. */
static int csgm_narrow(int paths, const int16_t* p2lut, int have_cost) {
    if (have_cost) return 0;
    int hi = 0;
    for (int i = 0; i < 256; i++) {
        if (p2lut[i] < 0) return 0;
        if (p2lut[i] > hi) hi = p2lut[i];
    }
    return (paths / 2) * (24 + hi) <= 255;
}

/* Whether the path costs are uint8 as well (csgm_pass_row8): the AVX2 build, narrow partial sums, 8 paths
 * and D a multiple of 16. */
static int csgm_narrow8(int paths, const int16_t* p2lut, int have_cost, int D) {
#if defined(__AVX2__)
    return paths == 8 && (D & 15) == 0 && csgm_narrow(paths, p2lut, have_cost);
#else
    (void)paths, (void)p2lut, (void)have_cost, (void)D;
    return 0;
#endif
}

/* Whether the row finisher's WTAs run on 16-bit keys (csgm_wta_keys): the AVX2 build, narrow partial sums
 * and D <= 128. */
static int csgm_packed(int paths, const int16_t* p2lut, int have_cost, int D) {
#if defined(__AVX2__)
    return D <= 128 && csgm_narrow(paths, p2lut, have_cost);
#else
    (void)paths, (void)p2lut, (void)have_cost, (void)D;
    return 0;
#endif
}

/* Per-thread scratch (bytes), see csgm_scratch_bytes. */
typedef struct {
    int16_t* rowP; /* 3 planes x W x csgm_stride(D): path costs of the previous row */
    int16_t* rowC; /* same, current row */
    int16_t* minP; /* 3 x W */
    int16_t* minC;
    int16_t* hA; /* csgm_stride(D) */
    int16_t* hB;
    int16_t* zero; /* csgm_stride(D) zeros: the "previous pixel" of a path's first pixel */
    uint16_t* part; /* W x D: this pass's partial sum of the row */
    uint16_t* sum;  /* D: a pixel's full sum (finishing a row) */
    uint16_t* crow; /* D: a pixel's Hamming costs (computed in the pass, used at once) */
    uint32_t* rev;  /* W: right census codes reversed */
    uint16_t* rbc;  /* W + 16: right WTA best cost (reversed x), or best key (p->packed) */
    uint16_t* rbd;  /* W: right WTA best d */
    uint16_t* keys; /* CSGM_KEYS: a pixel's keys (p->packed), see csgm_pack_px */
} csgm_thread;

static size_t csgm_align(size_t n) { return (n + 63) & ~(size_t)63; }

/* A pixel's path costs in a buffer: CSGM_OFF int16 of which the last is the sentinel left of d = 0, the D
 * costs (32-byte aligned when D is a multiple of 16), the sentinel right of d = D - 1, padding. */
#define CSGM_OFF 16
/* A pixel's keys: 16 entries 0xFFFF, the 128 keys of d = 0 .. 127, 16 entries 0xFFFF (csgm_pack_px). */
#define CSGM_KEYS (16 + 128 + 16)
static size_t csgm_stride(int D) { return ((size_t)D + CSGM_OFF + 1 + 15) & ~(size_t)15; }

static size_t csgm_scratch_bytes(int W, int D) {
    size_t s = csgm_stride(D);
    size_t b = 0;
    b += 2 * csgm_align(3 * (size_t)W * s * 2);
    b += 2 * csgm_align(3 * (size_t)W * 2);
    b += 3 * csgm_align(s * 2);
    b += csgm_align((size_t)W * D * 2) + 2 * csgm_align(((size_t)D + 32) * 2); /* part; sum, crow (+ 32: csgm_step4_u8) */
    b += csgm_align((size_t)W * 4);
    b += csgm_align(((size_t)W + 16) * 2) + csgm_align((size_t)W * 2);
    b += csgm_align(CSGM_KEYS * 2);
    return b + 64;
}

static void csgm_thread_init(csgm_thread* t, uint8_t* base, int W, int D) {
    size_t s = csgm_stride(D);
    uint8_t* p = (uint8_t*)(((uintptr_t)base + 63) & ~(uintptr_t)63);
#define CSGM_TAKE(field, type, count)        \
    t->field = (type*)p;                     \
    p += csgm_align((size_t)(count) * sizeof(type));
    CSGM_TAKE(rowP, int16_t, 3 * (size_t)W * s)
    CSGM_TAKE(rowC, int16_t, 3 * (size_t)W * s)
    CSGM_TAKE(minP, int16_t, 3 * (size_t)W)
    CSGM_TAKE(minC, int16_t, 3 * (size_t)W)
    CSGM_TAKE(hA, int16_t, s)
    CSGM_TAKE(hB, int16_t, s)
    CSGM_TAKE(zero, int16_t, s)
    CSGM_TAKE(part, uint16_t, (size_t)W * D)
    CSGM_TAKE(sum, uint16_t, (size_t)D + 32)
    CSGM_TAKE(crow, uint16_t, (size_t)D + 32)
    CSGM_TAKE(rev, uint32_t, W)
    CSGM_TAKE(rbc, uint16_t, (size_t)W + 16)
    CSGM_TAKE(rbd, uint16_t, W)
    CSGM_TAKE(keys, uint16_t, CSGM_KEYS)
#undef CSGM_TAKE
    memset(t->keys, 0xFF, CSGM_KEYS * sizeof(uint16_t)); /* keys of d >= D and the padding: never written */
    /* sentinels left of d = 0 and right of d = D - 1 (never overwritten) */
    for (size_t i = 0; i < 3 * (size_t)W; i++) {
        t->rowP[i * s + CSGM_OFF - 1] = t->rowP[i * s + CSGM_OFF + D] = CSGM_SENT;
        t->rowC[i * s + CSGM_OFF - 1] = t->rowC[i * s + CSGM_OFF + D] = CSGM_SENT;
    }
    t->hA[CSGM_OFF - 1] = t->hA[CSGM_OFF + D] = t->hB[CSGM_OFF - 1] = t->hB[CSGM_OFF + D] = CSGM_SENT;
    memset(t->zero, 0, s * sizeof(int16_t));
}

#if defined(__AVX2__)
static size_t csgm_stride8(int D);
/* The row buffers of t for csgm_pass_row8 (they fit in those of csgm_thread_init: csgm_stride8(D) bytes <
 * 2 csgm_stride(D)): everything the sentinel 0xFF, the path start's row 0. */
static void csgm_thread_init8(csgm_thread* t, int W, int D) {
    const size_t s8 = csgm_stride8(D);
    memset(t->rowP, 0xFF, 3 * (size_t)W * s8);
    memset(t->rowC, 0xFF, 3 * (size_t)W * s8);
    memset(t->hA, 0xFF, s8);
    memset(t->hB, 0xFF, s8);
    memset(t->zero, 0, s8);
}
#endif

/* After a row of a pass: the current row's path costs and minima become the previous row's. */
CSGM_INLINE void csgm_next_row(csgm_thread* t) {
    int16_t* tmp = t->rowP;
    t->rowP = t->rowC;
    t->rowC = tmp;
    tmp = t->minP;
    t->minP = t->minC;
    t->minC = tmp;
}

/* The costs of pixel x (n valid disparities): row crow of the cost volume, else (crow == NULL) the Hamming
 * costs of clr[x] and the reversed right codes rev, computed into buf (D entries). */
CSGM_INLINE const uint16_t* csgm_costs_px(const uint16_t* crow, const uint32_t* clr, const uint32_t* rev,
                                          uint16_t* buf, int W, int x, int n, int D) {
    if (crow) return crow + (ptrdiff_t)x * D;
    csgm_hamming_px(clr[x], rev + (W - 1 - x), buf, n, D, 0);
    return buf;
}

#if defined(__AVX2__)
/* ------------------------------------------------- SGM with uint8 path costs --
 * When the partial sums are narrow, every path cost fits uint8 as well: L = C + (v - pm) with
 * pm <= v <= pm + P2, so L <= 24 + P2 and 4 (24 + max P2) <= 255.  csgm_pass_row8 then keeps the path
 * costs as bytes (32 disparities per instruction, half the bytes of the row buffers) with 0xFF as the
 * sentinel: saturating adds keep it at 0xFF, so it never wins a minimum.  The same integers as
 * csgm_step4: every intermediate value of a valid lane is below 255 (pm + P2 <= 63 + 39 and
 * L' + P1 saturating only when L' is the sentinel). */
#define CSGM_OFF8 16
static size_t csgm_stride8(int D) { return CSGM_OFF8 + (((size_t)D + 31) & ~(size_t)31) + 16; }

CSGM_INLINE int16_t csgm_hmin8(__m256i v) {
    __m128i h = _mm_min_epu8(_mm256_castsi256_si128(v), _mm256_extracti128_si256(v, 1));
    h = _mm_min_epu8(h, _mm_srli_epi16(h, 8));
    return (int16_t)_mm_cvtsi128_si32(_mm_minpos_epu16(_mm_and_si128(h, _mm_set1_epi16(0xFF))));
}

/* csgm_step4 on uint8 path costs; C: the pixel's Hamming costs (uint16, readable up to round32(D)). */
CSGM_INLINE void csgm_step4_u8(const uint16_t* CSGM_RESTRICT C, const uint8_t* CSGM_RESTRICT p0,
                               const uint8_t* CSGM_RESTRICT p1, const uint8_t* CSGM_RESTRICT p2,
                               const uint8_t* CSGM_RESTRICT p3, uint8_t* CSGM_RESTRICT c0,
                               uint8_t* CSGM_RESTRICT c1, uint8_t* CSGM_RESTRICT c2, uint8_t* CSGM_RESTRICT c3,
                               const int16_t* pm, const int16_t* P2, int16_t* m, uint8_t* CSGM_RESTRICT acc,
                               int n, int D, int16_t P1) {
    const __m256i vp1 = _mm256_set1_epi8((char)P1);
    const __m256i pm0 = _mm256_set1_epi8((char)pm[0]), pm1 = _mm256_set1_epi8((char)pm[1]);
    const __m256i pm2 = _mm256_set1_epi8((char)pm[2]), pm3 = _mm256_set1_epi8((char)pm[3]);
    const __m256i j0 = _mm256_set1_epi8((char)(pm[0] + P2[0])), j1 = _mm256_set1_epi8((char)(pm[1] + P2[1]));
    const __m256i j2 = _mm256_set1_epi8((char)(pm[2] + P2[2])), j3 = _mm256_set1_epi8((char)(pm[3] + P2[3]));
    const __m256i sent = _mm256_set1_epi8((char)0xFF);
    const __m256i lane = _mm256_setr_epi8(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17, 18, 19, 20,
                                          21, 22, 23, 24, 25, 26, 27, 28, 29, 30, 31);
    __m256i m0 = sent, m1 = sent, m2 = sent, m3 = sent;
#define CSGM_LD8(q) _mm256_loadu_si256((const __m256i*)(q))
#define CSGM_VPATH8(p, c, pmk, jk, mk, Lk)                                                             \
    __m256i Lk = _mm256_adds_epu8(_mm256_min_epu8(CSGM_LD8(p + d - 1), CSGM_LD8(p + d + 1)), vp1);    \
    Lk = _mm256_min_epu8(_mm256_min_epu8(Lk, CSGM_LD8(p + d)), jk);                                    \
    Lk = _mm256_blendv_epi8(sent, _mm256_adds_epu8(_mm256_subs_epu8(Lk, pmk), cd), keep);              \
    _mm256_storeu_si256((__m256i*)(c + d), Lk);                                                        \
    mk = _mm256_min_epu8(mk, Lk);
    int d = 0;
    for (; d < n; d += 32) {
        const __m256i keep = d + 32 <= n ? sent : _mm256_cmpgt_epi8(_mm256_set1_epi8((char)(n - d)), lane);
        const __m256i cd = _mm256_permute4x64_epi64(
            _mm256_packus_epi16(CSGM_LD8(C + d), CSGM_LD8(C + d + 16)), 0xD8);
        CSGM_VPATH8(p0, c0, pm0, j0, m0, L0)
        CSGM_VPATH8(p1, c1, pm1, j1, m1, L1)
        CSGM_VPATH8(p2, c2, pm2, j2, m2, L2)
        CSGM_VPATH8(p3, c3, pm3, j3, m3, L3)
        const __m256i sum = _mm256_adds_epu8(_mm256_adds_epu8(L0, L1), _mm256_adds_epu8(L2, L3));
        if (d + 32 <= D)
            _mm256_storeu_si256((__m256i*)(acc + d), sum);
        else /* D % 32 == 16: the first 16 bytes only (acc + D is the next pixel's) */
            _mm_storeu_si128((__m128i*)(acc + d), _mm256_castsi256_si128(sum));
    }
#undef CSGM_VPATH8
#undef CSGM_LD8
    for (; d < D; d += 32) {
        _mm256_storeu_si256((__m256i*)(c0 + d), sent);
        _mm256_storeu_si256((__m256i*)(c1 + d), sent);
        _mm256_storeu_si256((__m256i*)(c2 + d), sent);
        _mm256_storeu_si256((__m256i*)(c3 + d), sent);
    }
    m[0] = csgm_hmin8(m0);
    m[1] = csgm_hmin8(m1);
    m[2] = csgm_hmin8(m2);
    m[3] = csgm_hmin8(m3);
}

/* csgm_pass_row with uint8 path costs (p->narrow8): the row buffers of t hold csgm_stride8(D) bytes per
 * pixel and path (csgm_thread_init8). */
static void csgm_pass_row8(const csgm_params* p, const uint8_t* CSGM_RESTRICT g, csgm_thread* t, int y, int s,
                           int first, uint8_t* CSGM_RESTRICT part) {
    const int W = p->W, D = p->D;
    const ptrdiff_t st = (ptrdiff_t)csgm_stride8(D);
    const ptrdiff_t plane = (ptrdiff_t)W * st;
    const int16_t P1 = (int16_t)p->P1;
    const int16_t* lut = p->p2lut;
    const uint32_t* clr = p->cl + (ptrdiff_t)y * W;
    const uint32_t* crr = p->cr + (ptrdiff_t)y * W;
    for (int x = 0; x < W; x++) t->rev[x] = crr[W - 1 - x];
    const uint8_t* grow = g + (ptrdiff_t)y * W;
    const uint8_t* gprev = first ? grow : g + (ptrdiff_t)(y - s) * W;
    uint8_t* rowP = (uint8_t*)t->rowP;
    uint8_t* rowC = (uint8_t*)t->rowC;
    const uint8_t* zero = (const uint8_t*)t->zero + CSGM_OFF8;
    uint8_t* hp = (uint8_t*)t->hA + CSGM_OFF8;
    uint8_t* hc = (uint8_t*)t->hB + CSGM_OFF8;
    int16_t hm = 0;
    for (int i = 0; i < W; i++) {
        const int x = s > 0 ? i : W - 1 - i;
        const int n = x + 1 < D ? x + 1 : D;
        const int gx = grow[x];
        int16_t pm[4], P2[4], m[4];
        const uint8_t* pv[4];
        uint8_t* cv[4];
        /* path 0: horizontal from x - s; paths 1..3: from (y - s, x - s * dk), dk = 1, 0, -1 */
        pv[0] = i == 0 ? zero : hp;
        pm[0] = i == 0 ? 0 : hm;
        P2[0] = i == 0 ? 0 : lut[csgm_absdiff(gx, grow[x - s])];
        cv[0] = hc;
        for (int k = 0; k < 3; k++) {
            const int xp = x - s * (1 - k);
            cv[k + 1] = rowC + k * plane + (ptrdiff_t)x * st + CSGM_OFF8;
            if (first || xp < 0 || xp >= W) {
                pv[k + 1] = zero;
                pm[k + 1] = 0;
                P2[k + 1] = 0;
            } else {
                pv[k + 1] = rowP + k * plane + (ptrdiff_t)xp * st + CSGM_OFF8;
                pm[k + 1] = t->minP[k * W + xp];
                P2[k + 1] = lut[csgm_absdiff(gx, gprev[xp])];
            }
        }
        csgm_hamming_px(clr[x], t->rev + (W - 1 - x), t->crow, n, D, 0);
        csgm_step4_u8(t->crow, pv[0], pv[1], pv[2], pv[3], cv[0], cv[1], cv[2], cv[3], pm, P2, m,
                      part + (size_t)x * D, n, D, P1);
        t->minC[x] = m[1];
        t->minC[W + x] = m[2];
        t->minC[2 * W + x] = m[3];
        hm = m[0];
        uint8_t* tmp = hp;
        hp = hc;
        hc = tmp;
    }
    csgm_next_row(t);
}
#endif


/* Row y of one pass (s = +1 forward: x ascending, predecessors in row y - 1 and x - 1; s = -1 backward).
 * Writes the row's partial sum (4 or 2 paths) to part (W x D); rowP/minP must hold row y - s (unless first). */
static void csgm_pass_row(const csgm_params* p, const uint16_t* CSGM_RESTRICT cost, const uint8_t* CSGM_RESTRICT g,
                          csgm_thread* t, int y, int s, int first, void* CSGM_RESTRICT part) {
#if defined(__AVX2__)
    if (p->narrow8) {
        csgm_pass_row8(p, g, t, y, s, first, (uint8_t*)part);
        return;
    }
#endif
    const int W = p->W, D = p->D;
    const ptrdiff_t st = (ptrdiff_t)csgm_stride(D);
    const int16_t P1 = (int16_t)p->P1;
    const int16_t* lut = p->p2lut;
    const int eight = p->paths == 8;
    const int narrow = p->narrow;
    const size_t es = narrow ? 1 : 2; /* bytes per partial sum */
    /* the costs: row y of the volume, or (cost == NULL) each pixel's Hamming costs just before its step */
    const uint16_t* crow = cost ? cost + (ptrdiff_t)y * W * D : NULL;
    const uint32_t* clr = cost ? NULL : p->cl + (ptrdiff_t)y * W;
    if (!cost) {
        const uint32_t* crr = p->cr + (ptrdiff_t)y * W;
        for (int x = 0; x < W; x++) t->rev[x] = crr[W - 1 - x];
    }
    const uint8_t* grow = g + (ptrdiff_t)y * W;
    const uint8_t* gprev = first ? grow : g + (ptrdiff_t)(y - s) * W;
    const int16_t* zero = t->zero + CSGM_OFF;
    int16_t* hp = t->hA + CSGM_OFF;
    int16_t* hc = t->hB + CSGM_OFF;
    int16_t hm = 0;
#if defined(__AVX2__)
    const ptrdiff_t plane = (ptrdiff_t)W * st; /* the interior-pixel path below */
#endif
    for (int i = 0; i < W; i++) {
        const int x = s > 0 ? i : W - 1 - i;
        const int n = x + 1 < D ? x + 1 : D;
        const int gx = grow[x];
        int16_t pm[4], P2[4], m[4];
#if defined(__AVX2__)
        if (eight && !first && i > 0 && i < W - 1 && (D & 15) == 0) { /* interior pixel: every path continues */
            const int xa = x - s, xb = x + s;
            int16_t* c1 = t->rowC + (ptrdiff_t)x * st + CSGM_OFF;
            pm[0] = hm;
            pm[1] = t->minP[xa];
            pm[2] = t->minP[W + x];
            pm[3] = t->minP[2 * W + xb];
            P2[0] = lut[csgm_absdiff(gx, grow[xa])];
            P2[1] = lut[csgm_absdiff(gx, gprev[xa])];
            P2[2] = lut[csgm_absdiff(gx, gprev[x])];
            P2[3] = lut[csgm_absdiff(gx, gprev[xb])];
            const uint16_t* Cx = csgm_costs_px(crow, clr, t->rev, t->crow, W, x, n, D);
            const int16_t* q1 = t->rowP + (ptrdiff_t)xa * st + CSGM_OFF;
            const int16_t* q2 = t->rowP + plane + (ptrdiff_t)x * st + CSGM_OFF;
            const int16_t* q3 = t->rowP + 2 * plane + (ptrdiff_t)xb * st + CSGM_OFF;
            void* acc = (uint8_t*)part + (size_t)x * D * es;
            if (narrow)
                csgm_step4_avx2(Cx, hp, q1, q2, q3, hc, c1, c1 + plane, c1 + 2 * plane, pm, P2, m, acc, n, D, P1, 1);
            else
                csgm_step4_avx2(Cx, hp, q1, q2, q3, hc, c1, c1 + plane, c1 + 2 * plane, pm, P2, m, acc, n, D, P1, 0);
            t->minC[x] = m[1];
            t->minC[W + x] = m[2];
            t->minC[2 * W + x] = m[3];
            hm = m[0];
            int16_t* tmp = hp;
            hp = hc;
            hc = tmp;
            continue;
        }
#endif
        const int16_t* pv[4];
        int16_t* cv[4];
        /* path 0: horizontal from x - s; paths 1..3: from (y - s, x - s * dk), dk = 1, 0, -1 (8 paths)
         * or path 1: from (y - s, x) (4 paths) */
        if (i == 0) {
            pv[0] = zero;
            pm[0] = 0;
            P2[0] = 0;
        } else {
            pv[0] = hp;
            pm[0] = hm;
            P2[0] = lut[csgm_absdiff(gx, grow[x - s])];
        }
        cv[0] = hc;
        const int nk = eight ? 3 : 1;
        for (int k = 0; k < nk; k++) {
            const int dk = eight ? 1 - k : 0;
            const int xp = x - s * dk;
            cv[k + 1] = t->rowC + ((ptrdiff_t)k * W + x) * st + CSGM_OFF;
            if (first || xp < 0 || xp >= W) {
                pv[k + 1] = zero;
                pm[k + 1] = 0;
                P2[k + 1] = 0;
            } else {
                pv[k + 1] = t->rowP + ((ptrdiff_t)k * W + xp) * st + CSGM_OFF;
                pm[k + 1] = t->minP[k * W + xp];
                P2[k + 1] = lut[csgm_absdiff(gx, gprev[xp])];
            }
        }
        const uint16_t* C = csgm_costs_px(crow, clr, t->rev, t->crow, W, x, n, D);
        void* acc = (uint8_t*)part + (size_t)x * D * es;
        if (eight) {
            int done = 0;
#if defined(__AVX2__)
            if ((D & 15) == 0) {
                csgm_step4_avx2(C, pv[0], pv[1], pv[2], pv[3], cv[0], cv[1], cv[2], cv[3], pm, P2, m, acc, n, D, P1,
                                narrow);
                done = 1;
            }
#endif
            if (!done && narrow)
                csgm_step4(C, pv[0], pv[1], pv[2], pv[3], cv[0], cv[1], cv[2], cv[3], pm, P2, m, acc, n, D, P1, 1);
            else if (!done)
                csgm_step4(C, pv[0], pv[1], pv[2], pv[3], cv[0], cv[1], cv[2], cv[3], pm, P2, m, acc, n, D, P1, 0);
            t->minC[x] = m[1];
            t->minC[W + x] = m[2];
            t->minC[2 * W + x] = m[3];
        } else {
            if (narrow)
                csgm_step2(C, pv[0], pv[1], cv[0], cv[1], pm, P2, m, acc, n, D, P1, 1);
            else
                csgm_step2(C, pv[0], pv[1], cv[0], cv[1], pm, P2, m, acc, n, D, P1, 0);
            t->minC[x] = m[1];
        }
        hm = m[0];
        int16_t* tmp = hp;
        hp = hc;
        hc = tmp;
    }
    csgm_next_row(t);
}

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

/* Left WTA of one pixel over its n valid disparities (lowest d on ties), uniqueness, parabola.  In the left
 * band (n < D) a minimum at the largest existing d = n - 1 is rejected: the match may lie beyond the image. */
CSGM_INLINE float csgm_wta_pixel(const uint16_t* CSGM_RESTRICT c, int n, int D, double uniqueness, int subpixel) {
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
    const int b = csgm_first_eq(c, n, bv);
    if (n < D && b == n - 1) return NAN;
    if (b >= 2 || b + 2 <= n - 1) { /* some d with |d - best| > 1 */
        uint16_t second = 0xFFFFu;
        d = 0;
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
        if (!((double)bv < uniqueness * (double)second)) return NAN;
    }
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
        out[x] = csgm_wta_pixel(S + (ptrdiff_t)x * D, n, D, uniqueness, subpixel);
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

/* The steps between the left-right check and the median, on one finished row (in place): reject matches
 * whose right pixel x - floor(d + 0.5) lies within margin columns of the border (NaN fails both tests; the
 * float32 comparisons of border.reject_border_matches), then close short gaps. */
static void csgm_post_row(const csgm_params* p, float* CSGM_RESTRICT row) {
    const int W = p->W;
    if (p->border_margin) {
        const int mg = p->border_margin;
        for (int x = 0; x < W; x++) {
            const float v = row[x] + 0.5f;
            row[x] = (v < (float)(x - mg + 1) && v >= (float)(x - (W - 1 - mg))) ? row[x] : NAN;
        }
    }
    if (p->gap_size) vpp_gap_row(row, row, W, p->gap_size, p->gap_step);
}

/* ---------------------------------------------------------------- median -- */

/* Row py of the (H + 2) x (W + 2) copy of src with NaN and the border as +inf. */
static void csgm_median_pad_row(const float* CSGM_RESTRICT src, int H, int W, float* CSGM_RESTRICT pad, int py) {
    float* d = pad + (ptrdiff_t)py * (W + 2);
    const int y = py - 1;
    if (y < 0 || y >= H) {
        for (int x = 0; x < W + 2; x++) d[x] = INFINITY;
        return;
    }
    const float* s = src + (ptrdiff_t)y * W;
    d[0] = d[W + 1] = INFINITY;
    for (int x = 0; x < W; x++) d[x + 1] = isnan(s[x]) ? INFINITY : s[x];
}

#define CSGM_CE(a, b)              \
    {                              \
        float lo_ = a < b ? a : b; \
        float hi_ = a < b ? b : a; \
        a = lo_;                   \
        b = hi_;                   \
    }
/* 25-comparator sorting network for 9 inputs, CE(a, b) leaves min in a, max in b */
#define CSGM_SORT9(CE)                                                                                      \
    CE(v0, v1) CE(v3, v4) CE(v6, v7) CE(v1, v2) CE(v4, v5) CE(v7, v8) CE(v0, v1) CE(v3, v4) CE(v6, v7)     \
    CE(v0, v3) CE(v3, v6) CE(v0, v3) CE(v1, v4) CE(v4, v7) CE(v1, v4) CE(v2, v5) CE(v5, v8) CE(v2, v5)     \
    CE(v1, v3) CE(v5, v7) CE(v2, v6) CE(v4, v6) CE(v2, v4) CE(v2, v3) CE(v5, v6)

#if defined(__AVX__)
#define CSGM_VW 8
typedef __m256 csgm_vf;
#define CSGM_VLOAD(p) _mm256_loadu_ps(p)
#define CSGM_VSTORE(p, v) _mm256_storeu_ps(p, v)
#define CSGM_VSET1(x) _mm256_set1_ps(x)
#define CSGM_VMIN(a, b) _mm256_min_ps(a, b)
#define CSGM_VMAX(a, b) _mm256_max_ps(a, b)
#define CSGM_VADD(a, b) _mm256_add_ps(a, b)
#define CSGM_VMUL(a, b) _mm256_mul_ps(a, b)
#define CSGM_VAND(a, b) _mm256_and_ps(a, b)
#define CSGM_VLT(a, b) _mm256_cmp_ps(a, b, _CMP_LT_OQ)
#define CSGM_VEQ(a, b) _mm256_cmp_ps(a, b, _CMP_EQ_OQ)
#define CSGM_VSEL(m, a, b) _mm256_blendv_ps(b, a, m)
#elif defined(__SSE2__)
#define CSGM_VW 4
typedef __m128 csgm_vf;
#define CSGM_VLOAD(p) _mm_loadu_ps(p)
#define CSGM_VSTORE(p, v) _mm_storeu_ps(p, v)
#define CSGM_VSET1(x) _mm_set1_ps(x)
#define CSGM_VMIN(a, b) _mm_min_ps(a, b)
#define CSGM_VMAX(a, b) _mm_max_ps(a, b)
#define CSGM_VADD(a, b) _mm_add_ps(a, b)
#define CSGM_VMUL(a, b) _mm_mul_ps(a, b)
#define CSGM_VAND(a, b) _mm_and_ps(a, b)
#define CSGM_VLT(a, b) _mm_cmplt_ps(a, b)
#define CSGM_VEQ(a, b) _mm_cmpeq_ps(a, b)
#define CSGM_VSEL(m, a, b) _mm_or_ps(_mm_and_ps(m, a), _mm_andnot_ps(m, b))
#endif

/* Row y of the 3x3 median over the finite neighbours (mean of the middle two for an even count);
 * NaN (inf in pad) stays NaN.  Sorts the 9 values (inf last) and picks by the finite count n. */
static void csgm_median_row(const float* CSGM_RESTRICT pad, int W, float* CSGM_RESTRICT out, int y) {
    const ptrdiff_t P = (ptrdiff_t)W + 2;
    const float* r0 = pad + (ptrdiff_t)y * P + 1;
    const float* r1 = r0 + P;
    const float* r2 = r1 + P;
    float* o = out + (ptrdiff_t)y * W;
    ptrdiff_t x = 0;
#ifdef CSGM_VW
    {
        const csgm_vf inf = CSGM_VSET1(INFINITY), one = CSGM_VSET1(1.0f), half = CSGM_VSET1(0.5f);
        const csgm_vf nan = CSGM_VSET1(NAN);
#define CSGM_VCE(a, b)                     \
    {                                      \
        csgm_vf lo_ = CSGM_VMIN(a, b);     \
        csgm_vf hi_ = CSGM_VMAX(a, b);     \
        a = lo_;                           \
        b = hi_;                           \
    }
        for (; x + CSGM_VW <= W; x += CSGM_VW) {
            csgm_vf v0 = CSGM_VLOAD(r0 + x - 1), v1 = CSGM_VLOAD(r0 + x), v2 = CSGM_VLOAD(r0 + x + 1);
            csgm_vf v3 = CSGM_VLOAD(r1 + x - 1), v4 = CSGM_VLOAD(r1 + x), v5 = CSGM_VLOAD(r1 + x + 1);
            csgm_vf v6 = CSGM_VLOAD(r2 + x - 1), v7 = CSGM_VLOAD(r2 + x), v8 = CSGM_VLOAD(r2 + x + 1);
            const csgm_vf valid = CSGM_VLT(v4, inf);
            csgm_vf n = CSGM_VAND(CSGM_VLT(v0, inf), one);
            n = CSGM_VADD(n, CSGM_VAND(CSGM_VLT(v1, inf), one));
            n = CSGM_VADD(n, CSGM_VAND(CSGM_VLT(v2, inf), one));
            n = CSGM_VADD(n, CSGM_VAND(CSGM_VLT(v3, inf), one));
            n = CSGM_VADD(n, CSGM_VAND(valid, one));
            n = CSGM_VADD(n, CSGM_VAND(CSGM_VLT(v5, inf), one));
            n = CSGM_VADD(n, CSGM_VAND(CSGM_VLT(v6, inf), one));
            n = CSGM_VADD(n, CSGM_VAND(CSGM_VLT(v7, inf), one));
            n = CSGM_VADD(n, CSGM_VAND(CSGM_VLT(v8, inf), one));
            CSGM_SORT9(CSGM_VCE)
            csgm_vf r = v4;
#define CSGM_PICK(k, val) r = CSGM_VSEL(CSGM_VEQ(n, CSGM_VSET1((float)(k))), val, r);
            CSGM_PICK(1, v0)
            CSGM_PICK(2, CSGM_VMUL(CSGM_VADD(v0, v1), half))
            CSGM_PICK(3, v1)
            CSGM_PICK(4, CSGM_VMUL(CSGM_VADD(v1, v2), half))
            CSGM_PICK(5, v2)
            CSGM_PICK(6, CSGM_VMUL(CSGM_VADD(v2, v3), half))
            CSGM_PICK(7, v3)
            CSGM_PICK(8, CSGM_VMUL(CSGM_VADD(v3, v4), half))
#undef CSGM_PICK
#undef CSGM_VCE
            CSGM_VSTORE(o + x, CSGM_VSEL(valid, r, nan));
        }
    }
#endif
    for (; x < W; x++) {
        float v0 = r0[x - 1], v1 = r0[x], v2 = r0[x + 1];
        float v3 = r1[x - 1], v4 = r1[x], v5 = r1[x + 1];
        float v6 = r2[x - 1], v7 = r2[x], v8 = r2[x + 1];
        const float centre = v4;
        int n = (v0 < INFINITY) + (v1 < INFINITY) + (v2 < INFINITY) + (v3 < INFINITY) + (v4 < INFINITY) +
                (v5 < INFINITY) + (v6 < INFINITY) + (v7 < INFINITY) + (v8 < INFINITY);
        CSGM_SORT9(CSGM_CE)
        float r = v4;
        r = n == 1 ? v0 : r;
        r = n == 2 ? (v0 + v1) * 0.5f : r;
        r = n == 3 ? v1 : r;
        r = n == 4 ? (v1 + v2) * 0.5f : r;
        r = n == 5 ? v2 : r;
        r = n == 6 ? (v2 + v3) * 0.5f : r;
        r = n == 7 ? v3 : r;
        r = n == 8 ? (v3 + v4) * 0.5f : r;
        o[x] = centre < INFINITY ? r : NAN;
    }
}
#undef CSGM_CE
#undef CSGM_SORT9

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
CSGM_INLINE float csgm_wta_keys(const uint16_t* CSGM_RESTRICT k, int n, int D, double uniqueness, int subpixel) {
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
    if (n < D && b == n - 1) return NAN;
    if (b >= 2 || b + 2 <= n - 1) { /* some d with |d - best| > 1 */
        const int base = (b - 1) & ~15, r = (b - 1) & 15; /* b - 1 .. b + 1: lanes r .. r + 2 (mod 16) */
        const __m256i rv = _mm256_set1_epi16((int16_t)r);
        const __m256i rel = _mm256_and_si256(_mm256_sub_epi16(lane, rv), _mm256_set1_epi16(15));
        const __m256i three = _mm256_cmpeq_epi16(_mm256_min_epu16(rel, _mm256_set1_epi16(2)), rel);
        const __m256i w = _mm256_blendv_epi8(_mm256_loadu_si256((const __m256i*)(k + base)),
                                             _mm256_loadu_si256((const __m256i*)(k + base + 16)),
                                             _mm256_cmpgt_epi16(rv, lane)); /* lanes < r: the next block */
        const __m256i use2 = _mm256_and_si256(three, _mm256_cmpeq_epi16(lo[0], w));
        const unsigned second = csgm_hmin16u(_mm256_blendv_epi8(lo[0], hi[0], use2)) >> 7;
        if (!((double)bv < uniqueness * (double)second)) return NAN;
    }
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

/* ---------------------------------------------------------------- driver -- */

/* Finish row y: S = a + b (a, b: the passes' partial sums of the row, uint8 when p->narrow); then either
 * copy S to sout (invalid entries CSGM_NOCOST) or run the left and right WTA (on keys when p->packed) and
 * the left-right check into dl, dr, lr. */
static void csgm_finish_row(const csgm_params* p, csgm_thread* t, const void* CSGM_RESTRICT a,
                            const void* CSGM_RESTRICT b, int y, uint16_t* sout, float* dl, float* dr,
                            float* lr) {
    const int W = p->W, D = p->D;
    const ptrdiff_t n = (ptrdiff_t)W * D;
    const int narrow = p->narrow;
    const uint8_t* CSGM_RESTRICT a8 = (const uint8_t*)a;
    const uint8_t* CSGM_RESTRICT b8 = (const uint8_t*)b;
    const uint16_t* CSGM_RESTRICT a16 = (const uint16_t*)a;
    const uint16_t* CSGM_RESTRICT b16 = (const uint16_t*)b;
    if (sout) {
        uint16_t* CSGM_RESTRICT S = sout + (ptrdiff_t)y * n;
        if (narrow)
            for (ptrdiff_t i = 0; i < n; i++) S[i] = (uint16_t)(a8[i] + b8[i]);
        else
            for (ptrdiff_t i = 0; i < n; i++) S[i] = (uint16_t)(a16[i] + b16[i]);
        for (int x = 0; x < W && x < D - 1; x++)
            for (int d = x + 1; d < D; d++) S[(ptrdiff_t)x * D + d] = CSGM_NOCOST;
        return;
    }
    /* pixel by pixel: its sum S (D entries, in L1), left WTA, right WTA update */
    uint16_t* CSGM_RESTRICT S = t->sum;
    float* l = dl ? dl + (ptrdiff_t)y * W : NULL;
    const int right = l && p->lr_check;
    if (right) {
        for (int i = 0; i < W + 16; i++) t->rbc[i] = 0xFFFFu;
        if (!p->packed)
            for (int i = 0; i < W; i++) t->rbd[i] = 0;
    }
#if defined(__AVX2__)
    if (p->packed) {
        uint16_t* CSGM_RESTRICT k = t->keys + 16;
        for (int x = 0; x < W; x++) {
            const int nv = x + 1 < D ? x + 1 : D;
            csgm_pack_px(a8 + (ptrdiff_t)x * D, b8 + (ptrdiff_t)x * D, k, nv, D);
            if (!l) continue; /* aggregation only (timing) */
            l[x] = csgm_wta_keys(k, nv, D, p->uniqueness, p->subpixel);
            if (right) csgm_right_keys(k, nv, t->rbc + (W - 1 - x));
        }
    } else
#endif
    for (int x = 0; x < W; x++) {
        const int nv = x + 1 < D ? x + 1 : D;
        if (narrow) {
            const uint8_t* CSGM_RESTRICT ax = a8 + (ptrdiff_t)x * D;
            const uint8_t* CSGM_RESTRICT bx = b8 + (ptrdiff_t)x * D;
            for (int d = 0; d < D; d++) S[d] = (uint16_t)(ax[d] + bx[d]);
        } else {
            const uint16_t* CSGM_RESTRICT ax = a16 + (ptrdiff_t)x * D;
            const uint16_t* CSGM_RESTRICT bx = b16 + (ptrdiff_t)x * D;
            for (int d = 0; d < D; d++) S[d] = (uint16_t)(ax[d] + bx[d]);
        }
        if (!l) continue; /* aggregation only (timing) */
        l[x] = csgm_wta_pixel(S, nv, D, p->uniqueness, p->subpixel);
        if (right) csgm_right_pixel(S, nv, t->rbc + (W - 1 - x), t->rbd + (W - 1 - x));
    }
    if (!l) return;
    if (!right) {
        if (lr != l) memcpy(lr + (ptrdiff_t)y * W, l, (size_t)W * sizeof(float));
    } else {
        float* r = dr + (ptrdiff_t)y * W;
        const uint16_t* best = p->packed ? t->rbc : t->rbd; /* keys: the disparity is the low 7 bits */
        const unsigned mask = p->packed ? 127u : 0xFFFFu;
        for (int xr = 0; xr < W; xr++) r[xr] = (float)(best[W - 1 - xr] & mask);
        csgm_lr_row(l, r, lr + (ptrdiff_t)y * W, W, p->tolerance);
    }
    csgm_post_row(p, lr + (ptrdiff_t)y * W);
}

/* One pass over all rows (s = +1 top-down, -1 bottom-up).  Each row's partial sum goes to the thread's
 * scratch row (in cache whichever way x runs).  A pass that reaches a row first copies it to own[y] and
 * counts the row; the pass that comes second (the other had counted it) finishes the row from its scratch
 * and other[y].  own is NULL for the one-thread backward pass (always second). */
static void csgm_pass(const csgm_params* p, const uint16_t* cost, const uint8_t* g, csgm_thread* t, int s,
                      void* own, const void* other, int* rowcnt, uint16_t* sout, float* dl, float* dr,
                      float* lr) {
    const int H = p->H;
    const size_t n = (size_t)p->W * p->D * (p->narrow ? 1 : 2); /* bytes of a row of partial sums */
    for (int i = 0; i < H; i++) {
        const int y = s > 0 ? i : H - 1 - i;
        csgm_pass_row(p, cost, g, t, y, s, i == 0, t->part);
        /* first: store the row, then count it; the pass that counts second sees the other's row */
        if (own && __atomic_load_n(&rowcnt[y], __ATOMIC_ACQUIRE) == 0) {
            memcpy((uint8_t*)own + (size_t)y * n, t->part, n);
            if (__atomic_fetch_add(&rowcnt[y], 1, __ATOMIC_ACQ_REL) == 0) continue;
        }
        csgm_finish_row(p, t, t->part, (const uint8_t*)other + (size_t)y * n, y, sout, dl, dr, lr);
    }
}

/* Census of both images and (cost != NULL) the Hamming volume, by thread tid of a team (called inside a
 * parallel region: every thread of the team must call it).  padl, padr: (H + 4) x (W + 4) bytes; cl, cr: H x W
 * codes; work: team x csgm_cost_work_bytes(W) bytes (+ 64 for alignment). */
static size_t csgm_cost_work_bytes(int W) { return csgm_align((size_t)W * 4) + 3 * csgm_align((size_t)W); }

static void csgm_cost_team(const uint8_t* gl, const uint8_t* gr, int H, int W, int D, uint8_t* padl, uint8_t* padr,
                           uint32_t* cl, uint32_t* cr, uint16_t* cost, uint16_t invalid_cost, uint8_t* work, int tid,
                           int team) {
    const size_t wb = csgm_cost_work_bytes(W);
    uint8_t* w = (uint8_t*)(((uintptr_t)work + 63) & ~(uintptr_t)63) + (size_t)tid * wb;
    uint32_t* rev = (uint32_t*)w;
    uint8_t* b0 = w + csgm_align((size_t)W * 4);
    uint8_t* b1 = b0 + csgm_align((size_t)W);
    uint8_t* b2 = b1 + csgm_align((size_t)W);
    int p0 = (int)((int64_t)(H + 4) * tid / team), p1 = (int)((int64_t)(H + 4) * (tid + 1) / team);
    csgm_pad_rows(gl, H, W, padl, p0, p1);
    csgm_pad_rows(gr, H, W, padr, p0, p1);
#ifdef _OPENMP
#pragma omp barrier
#endif
    int y0 = (int)((int64_t)H * tid / team), y1 = (int)((int64_t)H * (tid + 1) / team);
    csgm_census_rows(padl, H, W, cl, y0, y1, b0, b1, b2);
    csgm_census_rows(padr, H, W, cr, y0, y1, b0, b1, b2);
    if (cost) {
#ifdef _OPENMP
#pragma omp barrier
#endif
        for (int y = y0; y < y1; y++)
            csgm_hamming_row(cl + (ptrdiff_t)y * W, cr + (ptrdiff_t)y * W, rev, cost + (ptrdiff_t)y * W * D, W, D,
                             invalid_cost);
    }
}

/* csgm_cost_team in a parallel region of its own. */
static void csgm_cost(const uint8_t* gl, const uint8_t* gr, int H, int W, int D, uint8_t* padl, uint8_t* padr,
                      uint32_t* cl, uint32_t* cr, uint16_t* cost, uint16_t invalid_cost, uint8_t* work,
                      int nthreads) {
    int nt = nthreads < 1 ? 1 : nthreads;
#ifdef _OPENMP
#pragma omp parallel num_threads(nt)
#endif
    {
        int tid, team;
        vpp_omp_team(&tid, &team);
        csgm_cost_team(gl, gr, H, W, D, padl, padr, cl, cr, cost, invalid_cost, work, tid, team);
    }
}

/* The census inputs of csgm_sgm when it starts with the census (else gl == NULL). */
typedef struct {
    const uint8_t* gl;
    const uint8_t* gr;
    uint8_t* padl;
    uint8_t* padr;
    uint8_t* work; /* nthreads x csgm_cost_work_bytes(W) + 64 */
} csgm_census_io;

/* SGM + WTA (+ right WTA, left-right check, median) of a cost volume (cost == NULL: of the Hamming costs of
 * p->cl, p->cr, computed row by row; with census, those codes are computed first, in the same region).
 * vf, vb: H x W x D uint16 partial-sum volumes (vb unused with one thread; when csgm_narrow holds, the
 * passes use their first H x W x D bytes as uint8 sums); rowcnt: H ints; scratch: blocks
 * of csgm_scratch_bytes(W, D); pad: (H + 2) x (W + 2) floats for the median.  With sout, writes the
 * aggregated volume there instead (no WTA).  Output: disp (H x W) = final disparity; dl, dr: left / right
 * WTA (dl may be disp when neither check nor median runs).  Only threads 0 and 1 use scratch (2 blocks). */
static void csgm_sgm(const csgm_params* p0, const uint16_t* cost, const uint8_t* g, uint16_t* vf, uint16_t* vb,
                     int* rowcnt, uint8_t* scratch, int nthreads, uint16_t* sout, float* dl, float* dr,
                     float* lr, float* pad, float* disp, const csgm_census_io* census) {
    csgm_params q = *p0;
    q.narrow = csgm_narrow(q.paths, q.p2lut, cost != NULL);
    q.narrow8 = csgm_narrow8(q.paths, q.p2lut, cost != NULL, q.D);
    q.packed = csgm_packed(q.paths, q.p2lut, cost != NULL, q.D);
    const csgm_params* p = &q;
    const int H = p->H, W = p->W;
    const size_t sb = csgm_scratch_bytes(W, p->D);
    int nt = nthreads < 1 ? 1 : nthreads;
    memset(rowcnt, 0, (size_t)H * sizeof(int));
#ifdef _OPENMP
#pragma omp parallel num_threads(nt)
#endif
    {
        int tid, team;
        vpp_omp_team(&tid, &team);
        if (census) { /* the census codes p->cl, p->cr first (all threads), then the passes read them */
            csgm_cost_team(census->gl, census->gr, H, W, p->D, census->padl, census->padr, (uint32_t*)p->cl,
                           (uint32_t*)p->cr, NULL, 0, census->work, tid, team);
#ifdef _OPENMP
#pragma omp barrier
#endif
        }
        csgm_thread t;
        if (tid < 2) {
            csgm_thread_init(&t, scratch + (size_t)tid * sb, W, p->D);
#if defined(__AVX2__)
            if (p->narrow8) csgm_thread_init8(&t, W, p->D);
#endif
        }
        if (team == 1) {
            csgm_pass(p, cost, g, &t, 1, vf, vf, rowcnt, sout, dl, dr, lr);
            csgm_pass(p, cost, g, &t, -1, NULL, vf, rowcnt, sout, dl, dr, lr);
        } else if (tid == 0) {
            csgm_pass(p, cost, g, &t, 1, vf, vb, rowcnt, sout, dl, dr, lr);
        } else if (tid == 1) {
            csgm_pass(p, cost, g, &t, -1, vb, vf, rowcnt, sout, dl, dr, lr);
        }
        if (!sout && dl && p->median) {
#ifdef _OPENMP
#pragma omp barrier
#endif
            const int y0 = (int)((int64_t)(H + 2) * tid / team), y1 = (int)((int64_t)(H + 2) * (tid + 1) / team);
            for (int py = y0; py < y1; py++) csgm_median_pad_row(lr, H, W, pad, py);
#ifdef _OPENMP
#pragma omp barrier
#endif
            const int z0 = (int)((int64_t)H * tid / team), z1 = (int)((int64_t)H * (tid + 1) / team);
            for (int y = z0; y < z1; y++) csgm_median_row(pad, W, disp, y);
        }
    }
}

#endif
