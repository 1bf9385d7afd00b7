/* Census-SGM, census and Hamming costs: the 5x5 census, a row of the Hamming volume, the cost stage (census of
 * both images, then the volume).
 * Built on _census_sgm_common.h; the driver, _census_sgm.h, includes it. */
#ifndef VPP_CENSUS_SGM_CENSUS_H
#define VPP_CENSUS_SGM_CENSUS_H

#include "_census_sgm_common.h"

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

/* The census inputs: the gray images and the census scratch (csgm_cost; csgm_sgm when it starts with the
 * census). */
typedef struct {
    const uint8_t* gl;
    const uint8_t* gr;
    uint8_t* padl;
    uint8_t* padr;
    uint8_t* work; /* nthreads x csgm_cost_work_bytes(W) + 64 */
} csgm_census_io;

/* csgm_cost_team in a parallel region of its own. */
static void csgm_cost(const csgm_census_io* io, int H, int W, int D, uint32_t* cl, uint32_t* cr, uint16_t* cost,
                      uint16_t invalid_cost, int nthreads) {
    int nt = nthreads < 1 ? 1 : nthreads;
#ifdef _OPENMP
#pragma omp parallel num_threads(nt)
#endif
    {
        int tid, team;
        vpp_omp_team(&tid, &team);
        csgm_cost_team(io->gl, io->gr, H, W, D, io->padl, io->padr, cl, cr, cost, invalid_cost, io->work, tid, team);
    }
}

#endif
