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
 *
 * The code is split by stage, as libSGM's: _census_sgm_common.h holds the common definitions (csgm_params),
 * which every stage header includes; this header holds the driver (row finishing, the passes over all rows, the
 * parallel region of csgm_sgm) and includes one header per stage, in pipeline order: _census_sgm_census.h (census, Hamming costs, the cost stage),
 * _census_sgm_paths.h (path aggregation), _census_sgm_wta.h (winner-takes-all, left-right check) and
 * _census_sgm_median.h (3x3 median).
 */
#ifndef VPP_CENSUS_SGM_H
#define VPP_CENSUS_SGM_H

#include "_census_sgm_common.h"

#include "_census_sgm_census.h"
#include "_census_sgm_paths.h"
#include "_census_sgm_wta.h"
#include "_census_sgm_median.h"

/* ---------------------------------------------------------------- driver -- */

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

#if defined(__AVX2__)
/* The WTAs of a row on keys (p->packed), see csgm_finish_row; cf NULL (a constant at one call site): no
 * confidence, the loop the compiler keeps for it has none of its work. */
CSGM_INLINE void csgm_wta_row_keys(const csgm_params* p, csgm_thread* t, const uint8_t* CSGM_RESTRICT a8,
                                   const uint8_t* CSGM_RESTRICT b8, float* l, int right, float* cf) {
    const int W = p->W, D = p->D;
    uint16_t* CSGM_RESTRICT k = t->keys + 16;
    for (int x = 0; x < W; x++) {
        const int nv = x + 1 < D ? x + 1 : D;
        csgm_pack_px(a8 + (ptrdiff_t)x * D, b8 + (ptrdiff_t)x * D, k, nv, D);
        if (!l) continue; /* aggregation only (timing) */
        l[x] = csgm_wta_keys(k, nv, D, p->uniqueness, p->subpixel, p->conf_peak, cf ? cf + x : NULL,
                             t->cbest + x);
        if (right) csgm_right_keys(k, nv, t->rbc + (W - 1 - x));
    }
}
#endif

/* The WTAs of a row on the plain sums, see csgm_finish_row and csgm_wta_row_keys. */
CSGM_INLINE void csgm_wta_row_sums(const csgm_params* p, csgm_thread* t, const void* CSGM_RESTRICT a,
                                   const void* CSGM_RESTRICT b, float* l, int right, float* cf) {
    const int W = p->W, D = p->D;
    const uint8_t* CSGM_RESTRICT a8 = (const uint8_t*)a;
    const uint8_t* CSGM_RESTRICT b8 = (const uint8_t*)b;
    const uint16_t* CSGM_RESTRICT a16 = (const uint16_t*)a;
    const uint16_t* CSGM_RESTRICT b16 = (const uint16_t*)b;
    uint16_t* CSGM_RESTRICT S = t->sum;
    for (int x = 0; x < W; x++) {
        const int nv = x + 1 < D ? x + 1 : D;
        if (p->narrow) {
            const uint8_t* CSGM_RESTRICT ax = a8 + (ptrdiff_t)x * D;
            const uint8_t* CSGM_RESTRICT bx = b8 + (ptrdiff_t)x * D;
            for (int d = 0; d < D; d++) S[d] = (uint16_t)(ax[d] + bx[d]);
        } else {
            const uint16_t* CSGM_RESTRICT ax = a16 + (ptrdiff_t)x * D;
            const uint16_t* CSGM_RESTRICT bx = b16 + (ptrdiff_t)x * D;
            for (int d = 0; d < D; d++) S[d] = (uint16_t)(ax[d] + bx[d]);
        }
        if (!l) continue; /* aggregation only (timing) */
        l[x] = csgm_wta_pixel(S, nv, D, p->uniqueness, p->subpixel, p->conf_peak, cf ? cf + x : NULL, t->cbest + x);
        if (right) csgm_right_pixel(S, nv, t->rbc + (W - 1 - x), t->rbd + (W - 1 - x));
    }
}

/* Finish row y: S = a + b (a, b: the passes' partial sums of the row, uint8 when p->narrow); then either
 * copy S to sout (invalid entries CSGM_NOCOST) or run the left and right WTA (on keys when p->packed) and
 * the left-right check into dl, dr, lr; with conf (not NULL) also the confidence of the row (the right WTA
 * then runs even without the check). */
static void csgm_finish_row(const csgm_params* p, csgm_thread* t, const void* CSGM_RESTRICT a,
                            const void* CSGM_RESTRICT b, int y, uint16_t* sout, float* dl, float* dr,
                            float* lr, float* conf) {
    const int W = p->W, D = p->D;
    const ptrdiff_t n = (ptrdiff_t)W * D;
    if (sout) {
        const uint8_t* CSGM_RESTRICT a8 = (const uint8_t*)a;
        const uint8_t* CSGM_RESTRICT b8 = (const uint8_t*)b;
        const uint16_t* CSGM_RESTRICT a16 = (const uint16_t*)a;
        const uint16_t* CSGM_RESTRICT b16 = (const uint16_t*)b;
        uint16_t* CSGM_RESTRICT S = sout + (ptrdiff_t)y * n;
        if (p->narrow)
            for (ptrdiff_t i = 0; i < n; i++) S[i] = (uint16_t)(a8[i] + b8[i]);
        else
            for (ptrdiff_t i = 0; i < n; i++) S[i] = (uint16_t)(a16[i] + b16[i]);
        for (int x = 0; x < W && x < D - 1; x++)
            for (int d = x + 1; d < D; d++) S[(ptrdiff_t)x * D + d] = CSGM_NOCOST;
        return;
    }
    /* pixel by pixel: its sum S (D entries, in L1) or keys, left WTA, right WTA update */
    float* l = dl ? dl + (ptrdiff_t)y * W : NULL;
    float* cf = l && conf ? conf + (ptrdiff_t)y * W : NULL;
    const int right = l && (p->lr_check || cf);
    if (right) {
        for (int i = 0; i < W + 16; i++) t->rbc[i] = 0xFFFFu;
        if (!p->packed)
            for (int i = 0; i < W; i++) t->rbd[i] = 0;
    }
#if defined(__AVX2__)
    if (p->packed) {
        if (cf)
            csgm_wta_row_keys(p, t, (const uint8_t*)a, (const uint8_t*)b, l, right, cf);
        else
            csgm_wta_row_keys(p, t, (const uint8_t*)a, (const uint8_t*)b, l, right, NULL);
    } else
#endif
    if (cf)
        csgm_wta_row_sums(p, t, a, b, l, right, cf);
    else
        csgm_wta_row_sums(p, t, a, b, l, right, NULL);
    if (!l) return;
    float* r = dr + (ptrdiff_t)y * W;
    if (right) {
        const uint16_t* best = p->packed ? t->rbc : t->rbd; /* keys: the disparity is the low 7 bits */
        const unsigned mask = p->packed ? 127u : 0xFFFFu;
        for (int xr = 0; xr < W; xr++) r[xr] = (float)(best[W - 1 - xr] & mask);
    }
    if (p->lr_check)
        csgm_lr_row(l, r, lr + (ptrdiff_t)y * W, W, p->tolerance);
    else if (lr != l)
        memcpy(lr + (ptrdiff_t)y * W, l, (size_t)W * sizeof(float));
    if (cf) csgm_conf_row(t->cbest, r, cf, W, p->tolerance + 1.0);
    csgm_post_row(p, lr + (ptrdiff_t)y * W);
}

/* One pass over all rows (s = +1 top-down, -1 bottom-up).  Each row's partial sum goes to the thread's
 * scratch row (in cache whichever way x runs).  A pass that reaches a row first copies it to own[y] and
 * counts the row; the pass that comes second (the other had counted it) finishes the row from its scratch
 * and other[y].  own is NULL for the one-thread backward pass (always second). */
static void csgm_pass(const csgm_params* p, const uint16_t* cost, const uint8_t* g, csgm_thread* t, int s,
                      void* own, const void* other, int* rowcnt, uint16_t* sout, float* dl, float* dr,
                      float* lr, float* conf) {
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
        csgm_finish_row(p, t, t->part, (const uint8_t*)other + (size_t)y * n, y, sout, dl, dr, lr, conf);
    }
}

/* The buffers of csgm_sgm.  With sout, it writes the aggregated volume there (no WTA); else disp is the
 * result (and conf, when set, its confidence), dl NULL stops after the aggregation (timing).  Only threads 0 and 1 use scratch (2 blocks). */
typedef struct {
    uint16_t* vf;     /* H x W x D partial sums (when csgm_narrow holds, the passes use the first H W D bytes as */
    uint16_t* vb;     /* uint8 sums); vb unused with one thread */
    int* rowcnt;      /* H */
    uint8_t* scratch; /* 2 blocks of csgm_scratch_bytes(W, D) (+ 64 for alignment) */
    uint16_t* sout;   /* H x W x D aggregated volume, or NULL */
    float* dl;        /* H x W left WTA (may be disp when neither check nor median runs) */
    float* dr;        /* H x W right WTA */
    float* lr;        /* H x W after the left-right check, border step and short gaps (may be dl) */
    float* pad;       /* (H + 2) x (W + 2) floats for the median */
    float* disp;      /* H x W final disparity */
    float* conf;      /* H x W confidence (csgm_conf_pixel, csgm_conf_row), or NULL: not computed */
} csgm_buffers;

/* SGM + WTA (+ right WTA, left-right check, median) of a cost volume (cost == NULL: of the Hamming costs of
 * p->cl, p->cr, computed row by row; with census, those codes are computed first, in the same region);
 * g: the left gray image (adaptive P2).  b: the buffers and outputs, see csgm_buffers. */
static void csgm_sgm(const csgm_params* p0, const uint16_t* cost, const uint8_t* g, const csgm_buffers* b,
                     const csgm_census_io* census, int nthreads) {
    uint16_t *vf = b->vf, *vb = b->vb, *sout = b->sout;
    int* rowcnt = b->rowcnt;
    uint8_t* scratch = b->scratch;
    float *dl = b->dl, *dr = b->dr, *lr = b->lr, *pad = b->pad, *disp = b->disp, *conf = b->conf;
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
            csgm_pass(p, cost, g, &t, 1, vf, vf, rowcnt, sout, dl, dr, lr, conf);
            csgm_pass(p, cost, g, &t, -1, NULL, vf, rowcnt, sout, dl, dr, lr, conf);
        } else if (tid == 0) {
            csgm_pass(p, cost, g, &t, 1, vf, vb, rowcnt, sout, dl, dr, lr, conf);
        } else if (tid == 1) {
            csgm_pass(p, cost, g, &t, -1, vb, vf, rowcnt, sout, dl, dr, lr, conf);
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
