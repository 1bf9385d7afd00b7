/* Speckle filter (speckle.remove_speckles): the connected components of a disparity map by union-find.
 *
 * Two 4-neighbours are joined when both are finite and their disparities in 1/16 px (rint(16 d)) differ by
 * at most max_diff16: the graph of OpenCV's filterSpeckles flood fill, so the components are the same.
 * Every component of at most max_size pixels becomes NaN.  In one parallel region:
 *   1. each thread quantises the rows of its strip and links every pixel to its left and upper neighbour
 *      (union-find over pixel indices: a root is the smallest index of its set; path halving);
 *   2. one thread links the strips across their borders, then makes every parent a root (in ascending
 *      order a parent, which is a smaller index, is already one) and counts the pixels of each root;
 *   3. each thread writes its share of the output. */
#ifndef VPP_SPECKLE_H
#define VPP_SPECKLE_H

#include <math.h>
#include <stdint.h>
#include <string.h>
#include "_omp_team.h"
#ifdef _OPENMP
#include <omp.h>
#endif

#define SPK_INVALID INT32_MIN

static inline int32_t spk_root(int32_t* parent, int32_t i) {
    while (parent[i] != i) {
        parent[i] = parent[parent[i]];
        i = parent[i];
    }
    return i;
}

static inline void spk_link(int32_t* parent, int32_t a, int32_t b) {
    a = spk_root(parent, a);
    b = spk_root(parent, b);
    if (a < b)
        parent[b] = a;
    else if (b < a)
        parent[a] = b;
}

static inline int spk_joined(const int32_t* q, int32_t a, int32_t b, int32_t max_diff16) {
    if (q[a] == SPK_INVALID || q[b] == SPK_INVALID) return 0;
    const int32_t e = q[a] - q[b];
    return (e < 0 ? -e : e) <= max_diff16;
}

/* Returns 0, or 1 (dst then undefined) when a finite |d| >= 32767 / 16 (1/16 px must fit int16).
 * q, parent, count: H * W int32 of scratch; dst may not be src. */
static int spk_filter(const float* src, float* dst, int H, int W, int32_t* q, int32_t* parent, int32_t* count,
                      int max_size, int max_diff16, int nthreads) {
    const int64_t n = (int64_t)H * W;
    int team_max = nthreads < 1 ? 1 : nthreads;
    if (team_max > H) team_max = H;
    int bad = 0;
#ifdef _OPENMP
#pragma omp parallel num_threads(team_max) reduction(| : bad)
#endif
    {
        int tid, team;
        vpp_omp_team(&tid, &team);
        const int y0 = (int)((int64_t)H * tid / team), y1 = (int)((int64_t)H * (tid + 1) / team);
        for (int y = y0; y < y1; y++) {
            for (int x = 0; x < W; x++) {
                const int32_t i = (int32_t)((int64_t)y * W + x);
                const float v = src[i];
                parent[i] = i;
                count[i] = 0;
                if (isfinite(v)) {
                    bad |= fabsf(v) >= 32767.0f / 16.0f;
                    q[i] = (int32_t)rintf(v * 16.0f);
                } else {
                    q[i] = SPK_INVALID;
                }
                if (x > 0 && spk_joined(q, i, i - 1, max_diff16)) spk_link(parent, i, i - 1);
                if (y > y0 && spk_joined(q, i, i - W, max_diff16)) spk_link(parent, i, i - W);
            }
        }
#ifdef _OPENMP
#pragma omp barrier
#endif
        /* bad is a reduction variable: each thread's own copy until the region ends, so the check is after it */
#ifdef _OPENMP
#pragma omp single
#endif
        {
            for (int t = 1; t < team; t++) {
                const int yb = (int)((int64_t)H * t / team);
                for (int x = 0; x < W; x++) {
                    const int32_t i = (int32_t)((int64_t)yb * W + x);
                    if (spk_joined(q, i, i - W, max_diff16)) spk_link(parent, i, i - W);
                }
            }
            for (int64_t i = 0; i < n; i++) {
                const int32_t r = parent[parent[i]];
                parent[i] = r;
                count[r] += q[i] != SPK_INVALID;
            }
        } /* implicit barrier */
        const int64_t i0 = n * tid / team, i1 = n * (tid + 1) / team;
        for (int64_t i = i0; i < i1; i++)
            dst[i] = (q[i] != SPK_INVALID && count[parent[i]] <= max_size) ? NAN : src[i];
    }
    return bad;
}

#endif
