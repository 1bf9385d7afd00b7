/* Census-SGM, path aggregation: the step of one pixel over the paths of a pass in its four forms (csgm_step4,
 * csgm_step2, csgm_step4_avx2, csgm_step4_u8), when the narrow forms apply, the per-thread scratch and one row
 * of a pass (csgm_pass_row, csgm_pass_row8).
 * Built on _census_sgm_common.h; the driver, _census_sgm.h, includes it. */
#ifndef VPP_CENSUS_SGM_PATHS_H
#define VPP_CENSUS_SGM_PATHS_H

#include "_census_sgm_common.h"

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
    uint16_t* cbest; /* W: the best d of each pixel of the row (confidence only, csgm_conf_pixel) */
} csgm_thread;

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
    b += csgm_align((size_t)W * 2); /* cbest */
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
    CSGM_TAKE(cbest, uint16_t, W)
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

#endif
