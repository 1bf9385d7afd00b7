/* Census-SGM, the 3x3 median over the valid neighbours.
 * Built on _census_sgm_common.h; the driver, _census_sgm.h, includes it. */
#ifndef VPP_CENSUS_SGM_MEDIAN_H
#define VPP_CENSUS_SGM_MEDIAN_H

#include "_census_sgm_common.h"

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

#endif
