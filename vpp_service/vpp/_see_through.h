/* See-through filter over a sparse disparity map (see_through.filter_see_through; wrapped by _see_through.pyx).
 *
 * A point d (finite, > 0) is dropped when the (2 rx + 1) x (2 ry + 1) window around it, clipped at the image
 * border, holds a value > max(d (1 + margin), d + min_gap).  Every other value (NaN, <= 0, inf) is "no point",
 * written as NaN.
 *
 * Window maxima in O(1) per pixel: vertically with van Herk / Gil-Werman blocks of 2 ry + 1 rows (the
 * block's suffix maxima and the running prefix maximum of the current block; two blocks of suffix rows kept),
 * streamed over the rows with ry zero rows of padding at both ends; horizontally by doubling (log2 passes over
 * the row padded with rx zeros).  Every loop is branch-free and vectorised by the compiler. */
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

/* dst[x] = max(a[x], b[x]) */
static inline void vpp_st_max2(float* restrict dst, const float* restrict a, const float* restrict b, int W) {
    for (int x = 0; x < W; x++) dst[x] = a[x] > b[x] ? a[x] : b[x];
}

/* In place: m[x] = max(m[x .. x + w - 1]) for x < n, where m holds n + w - 1 values (w >= 1). Doubling:
 * maxima over 2, 4, ... values until the next doubling would pass w, then one pass that overlaps two. */
static void vpp_st_window_max(float* m, int n, int w) {
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

/* Returns the number of dropped points, or -1 when the buffers cannot be allocated. */
static long vpp_see_through(const float* src, float* dst, int H, int W, int rx, int ry, float margin,
                            float min_gap) {
    const int h = 2 * ry + 1;  /* block height = window height */
    const int wp = W + 2 * rx; /* padded row */
    const int P = H + 2 * ry;  /* padded rows */
    float* buf = (float*)malloc(sizeof(float) * ((size_t)2 * h * W + (size_t)W + (size_t)wp));
    if (buf == NULL) return -1;
    float* suffix[2] = {buf, buf + (size_t)h * W};
    float* prefix = buf + (size_t)2 * h * W; /* max of the current block's rows so far */
    float* win = prefix + W;                 /* window maxima of one row, rx zeros each side at first */
    const float grow = 1.0f + margin;
    long dropped = 0;
    for (int j = 0; j < P; j++) {
        const int blk = j / h, off = j % h;
        const float* row = (j >= ry && j < ry + H) ? src + (size_t)(j - ry) * W : NULL;
        if (off == 0) memset(prefix, 0, sizeof(float) * (size_t)W);
        if (row != NULL) vpp_st_max_clean_into(prefix, row, W);
        if (off == h - 1 || j == P - 1) { /* block complete: its suffix maxima, last row first */
            float* s = suffix[blk & 1];
            const int j0 = blk * h;
            for (int i = off; i >= 0; i--) {
                float* si = s + (size_t)i * W;
                const int jj = j0 + i;
                if (i < off)
                    memcpy(si, si + W, sizeof(float) * (size_t)W);
                else
                    memset(si, 0, sizeof(float) * (size_t)W);
                if (jj >= ry && jj < ry + H) vpp_st_max_clean_into(si, src + (size_t)(jj - ry) * W, W);
            }
        }
        const int y = j - 2 * ry; /* the output row whose window ends at padded row j */
        if (y < 0) continue;
        /* vertical maxima of padded rows [y, y + 2 ry] = max(suffix of y in its block, prefix up to j) */
        memset(win, 0, sizeof(float) * (size_t)rx);
        memset(win + rx + W, 0, sizeof(float) * (size_t)rx);
        vpp_st_max2(win + rx, suffix[(y / h) & 1] + (size_t)(y % h) * W, prefix, W);
        vpp_st_window_max(win, W, 2 * rx + 1);
        const float* restrict in = src + (size_t)y * W;
        float* restrict out = dst + (size_t)y * W;
        const float* restrict wmax = win;
        int32_t n = 0;
        for (int x = 0; x < W; x++) {
            int32_t bits, nearer, keep, ob;
            float d;
            memcpy(&bits, &in[x], sizeof bits);
            const int32_t point = vpp_st_point(bits);
            bits &= point;
            memcpy(&d, &bits, sizeof d);
            const float rel = d * grow, gap = d + min_gap;
            const float t = rel > gap ? rel : gap;
            nearer = point & -(int32_t)(wmax[x] > t);
            n -= nearer;
            keep = point & ~nearer;
            ob = (bits & keep) | (VPP_ST_NAN & ~keep);
            memcpy(&out[x], &ob, sizeof ob);
        }
        dropped += n;
    }
    free(buf);
    return dropped;
}

#endif
