/* See-through filter over a sparse disparity map (see_through.filter_see_through; wrapped by _see_through.pyx).
 *
 * A point d (finite, > 0) is dropped when, within the (2 rx + 1) x (2 ry + 1) window around it (clipped at the
 * image border), clearly nearer values (> max(d (1 + margin), d + min_gap)) lie on two opposite sides: both in
 * the columns left of it and in the columns right of it, or both in the rows above and in the rows below.
 * Every other value (NaN, <= 0, inf) is "no point", written as NaN.
 *
 * Window maxima: the maxima of the ry rows ending at each row j, S(j), by van Herk / Gil-Werman blocks of ry
 * rows (the block's suffix maxima and the running prefix maximum; two blocks of suffix rows kept), streamed
 * over the rows with S kept for ry + 2 rows: above row y is S(y - 1), below it S(y + ry).  Horizontally by
 * doubling over the row padded with zeros.  Every loop is branch-free and vectorised by the compiler. */
#ifndef VPP_SEE_THROUGH_H
#define VPP_SEE_THROUGH_H

#include <stdint.h>
#include <stdlib.h>
#include <string.h>

/* All ones when the float with these bits is a point (finite and > 0, i.e. bits in [1, 0x7f7fffff]), else 0.
 * Tested on the bits, not with float comparisons: comparing a NaN may raise FE_INVALID, so the compiler
 * keeps such comparisons behind branches and does not vectorise the loop. */
static inline int32_t vpp_st_point(int32_t bits) { return -(int32_t)((uint32_t)(bits - 1) < 0x7f7fffffu); }


#define VPP_ST_NAN ((int32_t)0x7fc00000) /* quiet NaN */

/* Inlined into each specialisation of vpp_see_through, so that a constant window width shapes every loop. */
#if defined(__GNUC__) || defined(__clang__)
#define VPP_ST_INLINE static inline __attribute__((always_inline))
#elif defined(_MSC_VER)
#define VPP_ST_INLINE static __forceinline
#else
#define VPP_ST_INLINE static inline
#endif

/* acc = max(acc, src with every non-point as +0) */
static inline void vpp_st_max_clean_into(float* restrict acc, const float* restrict src, int W) {
    for (int x = 0; x < W; x++) {
        int32_t bits;
        float v;
        memcpy(&bits, &src[x], sizeof bits);
        bits &= vpp_st_point(bits);
        memcpy(&v, &bits, sizeof v);
        acc[x] = v > acc[x] ? v : acc[x];
    }
}

/* acc = max(acc, src) */
static inline void vpp_st_max_into(float* restrict acc, const float* restrict src, int W) {
    for (int x = 0; x < W; x++) acc[x] = src[x] > acc[x] ? src[x] : acc[x];
}

/* dst[x] = max(a[x], b[x]) */
static inline void vpp_st_max2(float* restrict dst, const float* restrict a, const float* restrict b, int W) {
    for (int x = 0; x < W; x++) dst[x] = a[x] > b[x] ? a[x] : b[x];
}

/* In place: m[x] = max(m[x .. x + w - 1]) for x < n, where m holds n + w - 1 values (w >= 1). Doubling:
 * maxima over 2, 4, ... values until the next doubling would pass w, then one pass that overlaps two. */
VPP_ST_INLINE void vpp_st_window_max(float* m, int n, int w) {
    int have = 1; /* m[x] = max over `have` values */
    while (2 * have <= w) {
        const int len = n + w - 2 * have; /* entries still needed */
        for (int x = 0; x < len; x++) m[x] = m[x + have] > m[x] ? m[x + have] : m[x];
        have *= 2;
    }
    if (have < w) {
        const int shift = w - have;
        for (int x = 0; x < n; x++) m[x] = m[x + shift] > m[x] ? m[x + shift] : m[x];
    }
}

/* One output row: the points of `in` (NaN elsewhere) less those with clearly nearer values on two opposite
 * sides; returns how many were dropped. */
static int32_t vpp_st_output_row(const float* restrict in, const float* restrict left, const float* restrict right,
                                 const float* restrict up, const float* restrict down, float* restrict out, int W,
                                 float grow, float min_gap) {
    int32_t cnt = 0;
    for (int x = 0; x < W; x++) {
        int32_t bits;
        float v;
        memcpy(&bits, &in[x], sizeof bits);
        const int32_t point = vpp_st_point(bits);
        bits &= point;
        memcpy(&v, &bits, sizeof v);
        const float rel = v * grow, gap = v + min_gap;
        const float t = rel > gap ? rel : gap;
        const int32_t sides = ((left[x] > t) & (right[x] > t)) | ((up[x] > t) & (down[x] > t));
        const int32_t hidden = point & -sides;
        cnt -= hidden;
        const int32_t keep = point & ~hidden;
        const int32_t ob = (bits & keep) | (VPP_ST_NAN & ~keep);
        memcpy(&out[x], &ob, sizeof ob);
    }
    return cnt;
}

/* Number of points in a row. */
static inline int32_t vpp_st_count(const float* restrict in, int W) {
    int32_t n = 0;
    for (int x = 0; x < W; x++) {
        int32_t bits;
        memcpy(&bits, &in[x], sizeof bits);
        n -= vpp_st_point(bits);
    }
    return n;
}

/* pad[0..W-1] = max over the window [x - r, x + r] of row v (W values, zeros beyond); pad holds W + 2 r floats.
 * Two rows at once (a -> pa, b -> pb): one pass over both per doubling step. */
VPP_ST_INLINE void vpp_st_centred_max2(const float* a, const float* b, float* restrict pa, float* restrict pb, int W,
                                int r) {
    const int w = 2 * r + 1;
    memset(pa, 0, sizeof(float) * (size_t)r);
    memset(pb, 0, sizeof(float) * (size_t)r);
    memcpy(pa + r, a, sizeof(float) * (size_t)W);
    memcpy(pb + r, b, sizeof(float) * (size_t)W);
    memset(pa + r + W, 0, sizeof(float) * (size_t)r);
    memset(pb + r + W, 0, sizeof(float) * (size_t)r);
    int have = 1;
    while (2 * have <= w) {
        const int len = W + w - 2 * have;
        for (int x = 0; x < len; x++) {
            pa[x] = pa[x + have] > pa[x] ? pa[x + have] : pa[x];
            pb[x] = pb[x + have] > pb[x] ? pb[x + have] : pb[x];
        }
        have *= 2;
    }
    if (have < w) {
        const int shift = w - have;
        for (int x = 0; x < W; x++) {
            pa[x] = pa[x + shift] > pa[x] ? pa[x + shift] : pa[x];
            pb[x] = pb[x + shift] > pb[x] ? pb[x + shift] : pb[x];
        }
    }
}

/* Returns the number of dropped points, or -1 when the buffers cannot be allocated. */
VPP_ST_INLINE long vpp_see_through_impl(const float* src, float* dst, int H, int W, int rx, int ry, float margin,
                                        float min_gap) {
    const int h = ry > 0 ? ry : 1; /* block height of the vertical maxima (windows of ry rows) */
    const int ring = ry + 2;       /* S(j) kept for the rows still to be output */
    const int wp = W + 2 * rx;
    const size_t n = (size_t)2 * h * W + (size_t)(ring + 3) * W + (size_t)3 * wp;
    float* buf = (float*)calloc(n, sizeof(float));
    if (buf == NULL) return -1;
    float* suffix[2] = {buf, buf + (size_t)h * W};
    float* prefix = buf + (size_t)2 * h * W; /* max of the current block's rows up to j */
    float* sring = prefix + W;               /* S(j) = max of rows [j - ry + 1, j], row j % ring */
    float* zero = sring + (size_t)ring * W;  /* stays zero */
    float* full = zero + W;                  /* column maxima over all 2 ry + 1 rows */
    float* upmax = full + W;                 /* window maxima over the rows above (wp floats) */
    float* downmax = upmax + wp;             /* ... and below (wp floats) */
    float* pad = downmax + wp;               /* left / right maxima (wp floats) */
    const float grow = 1.0f + margin;
    long dropped = 0;
    for (int j = 0; j < H + ry; j++) {
        float* sj = sring + (size_t)(j % ring) * W;
        if (ry > 0) {
            const int blk = j / h, off = j % h;
            if (off == 0) memset(prefix, 0, sizeof(float) * (size_t)W);
            if (j < H) vpp_st_max_clean_into(prefix, src + (size_t)j * W, W);
            if (off == h - 1) { /* block complete: its suffix maxima, last row first */
                float* sb = suffix[blk & 1];
                for (int i = h - 1; i >= 0; i--) {
                    float* si = sb + (size_t)i * W;
                    const int jj = blk * h + i;
                    if (i < h - 1)
                        memcpy(si, si + W, sizeof(float) * (size_t)W);
                    else
                        memset(si, 0, sizeof(float) * (size_t)W);
                    if (jj < H) vpp_st_max_clean_into(si, src + (size_t)jj * W, W);
                }
            }
            const int a = j - ry + 1; /* S(j) = max over rows [a, j] = max(suffix of a in its block, prefix) */
            if (a <= 0 || a % h == 0)
                memcpy(sj, prefix, sizeof(float) * (size_t)W); /* the window is the block so far */
            else
                vpp_st_max2(sj, suffix[(a / h) & 1] + (size_t)(a % h) * W, prefix, W);
        }
        const int y = j - ry; /* the output row whose rows below end at j */
        if (y < 0) continue;
        const float* up = (ry > 0 && y > 0) ? sring + (size_t)((y - 1) % ring) * W : zero;
        const float* down = ry > 0 ? sj : zero;
        const float* in = src + (size_t)y * W;
        float* out = dst + (size_t)y * W;
        if (vpp_st_count(in, W) == 0) { /* a row without points (most rows of a real scan) */
            const int32_t nan = VPP_ST_NAN;
            for (int x = 0; x < W; x++) memcpy(&out[x], &nan, sizeof nan);
            continue;
        }
        memcpy(full, up, sizeof(float) * (size_t)W);
        vpp_st_max_clean_into(full, in, W);
        vpp_st_max_into(full, down, W);
        vpp_st_centred_max2(up, down, upmax, downmax, W, rx);
        /* left of x: columns [x - rx, x - 1] = pad[x .. x + rx - 1]; right: [x + 1, x + rx] = pad[x + rx + 1 ..]
         * with pad = full between rx zeros each side, turned into maxima of rx values */
        const float* left = zero;
        const float* right = zero;
        if (rx > 0) {
            memset(pad, 0, sizeof(float) * (size_t)rx);
            memcpy(pad + rx, full, sizeof(float) * (size_t)W);
            memset(pad + rx + W, 0, sizeof(float) * (size_t)rx);
            vpp_st_window_max(pad, W + rx + 1, rx);
            left = pad;
            right = pad + rx + 1;
        }
        dropped += vpp_st_output_row(in, left, right, upmax, downmax, out, W, grow, min_gap);
    }
    free(buf);
    return dropped;
}

/* The filter; the common half-widths get their own copy of the loops (a constant rx: 1.12 -> 0.84 ms for
 * 5 x 11 on 1241 x 376 with 26 % points, AVX2 build). */
static long vpp_see_through(const float* src, float* dst, int H, int W, int rx, int ry, float margin,
                            float min_gap) {
    switch (rx) {
        case 1:
            return vpp_see_through_impl(src, dst, H, W, 1, ry, margin, min_gap);
        case 2:
            return vpp_see_through_impl(src, dst, H, W, 2, ry, margin, min_gap);
        case 3:
            return vpp_see_through_impl(src, dst, H, W, 3, ry, margin, min_gap);
        default:
            return vpp_see_through_impl(src, dst, H, W, rx, ry, margin, min_gap);
    }
}

#endif
