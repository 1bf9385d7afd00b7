/* Census-SGM, the common definitions: constants, inline/restrict macros, the parameter block (csgm_params) and
 * the row alignment.  Every stage header includes it, and so does the driver (_census_sgm.h). */
#ifndef VPP_CENSUS_SGM_COMMON_H
#define VPP_CENSUS_SGM_COMMON_H

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
    double conf_peak; /* confidence (csgm_conf_pixel): the peak-ratio margin 1 - best / second that counts as sure */
} csgm_params;

static size_t csgm_align(size_t n) { return (n + 63) & ~(size_t)63; }

#endif /* VPP_CENSUS_SGM_COMMON_H */
