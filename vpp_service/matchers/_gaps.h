/* Closing short interior gaps of one disparity row (holes.fill_short_gaps; shared by the _holes kernel and
 * the census-SGM kernel, which fills each row right after its left-right check). */
#ifndef VPP_GAPS_H
#define VPP_GAPS_H

#include <math.h>

/* dst = src with every interior NaN run of at most max_gap pixels filled: linearly between its ends when
 * they differ by at most max_step, else with the smaller end.  dst may be src. */
static void vpp_gap_row(const float* src, float* dst, int W, int max_gap, double max_step) {
    if (dst != src)
        for (int x = 0; x < W; x++) dst[x] = src[x];
    int x = 0;
    while (x < W) {
        if (!isnan(src[x])) {
            x++;
            continue;
        }
        int right = x;
        while (right < W && isnan(src[right])) right++;
        /* the gap spans [x, right); interior only, at most max_gap long */
        const int n = right - x;
        if (x > 0 && right < W && n <= max_gap) {
            const float a = src[x - 1], b = src[right];
            if (fabs((double)a - (double)b) <= max_step) {
                for (int j = 0; j < n; j++)
                    dst[x + j] = (float)((double)a + ((double)b - (double)a) * (j + 1) / (n + 1));
            } else {
                for (int j = x; j < right; j++) dst[j] = a < b ? a : b;
            }
        }
        x = right;
    }
}

#endif
