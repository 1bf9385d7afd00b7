"""Census-SGM kernels (nogil, typed memoryviews; the C is in ``_census_sgm.h`` and the headers it includes).

Low-level, unchecked kernels behind :mod:`vpp_service.matchers.census_sgm`;
the Python wrappers there validate every argument (shape, dtype, contiguity)
and allocate the outputs. Call those, not these.

The C, by stage (``setup.py`` rebuilds this module when a header named here
changes): ``_census_sgm.h`` (the driver: row finishing, the passes, the
parallel region) includes the stage headers ``_census_sgm_census.h``
(census, Hamming costs), ``_census_sgm_paths.h`` (path aggregation),
``_census_sgm_wta.h`` (winner-takes-all, left-right check) and
``_census_sgm_median.h`` (3x3 median); each of them and the driver include
``_census_sgm_common.h`` (the parameter block and macros), which includes
``_gaps.h`` (short gaps) and ``_omp_team.h``.

This source is compiled twice (``_census_sgm`` portable, ``_census_sgm_avx2``
for x86-64-v3); :mod:`vpp_service.matchers.census_sgm` picks the build that
:mod:`vpp_service.vpp.backend` picks for the VPP kernel. The loops in the
header are written for the compiler to vectorise; both builds give the same
integers.

Conventions
-----------
* cost / aggregated volumes are C-contiguous ``H x W x D`` uint16, ``d``
  fastest, disparity ``d`` matching left ``x`` with right ``x - d``; column
  ``x`` has the valid disparities ``d <= min(x, D - 1)`` (the others are
  never read; aggregated volumes hold 65535 there);
* path costs are int16 (uint8 in the AVX2 build when :func:`byte_path_costs`)
  in buffers padded with a sentinel on each side of the disparity axis, so the
  inner ``d`` loop has no branch and vectorises;
* every routine takes ``nthreads`` (>= 1) and opens one OpenMP parallel
  region (rows split in blocks; the SGM passes on two threads).
"""
from cython.parallel cimport prange, threadid
from libc.stdint cimport uint8_t, uint16_t, int16_t, uint32_t

import numpy as np


cdef extern from "_census_sgm.h" nogil:
    ctypedef struct csgm_params:
        int H
        int W
        int D
        int paths
        int P1
        const int16_t* p2lut
        double uniqueness
        int subpixel
        int lr_check
        int median
        double tolerance
        const uint32_t* cl
        const uint32_t* cr
        int narrow
        int narrow8
        int packed
        int border_margin
        int gap_size
        double gap_step
        double conf_peak
    int csgm_build_avx2()
    int csgm_narrow(int paths, const int16_t* p2lut, int have_cost)
    int csgm_narrow8(int paths, const int16_t* p2lut, int have_cost, int D)
    int csgm_packed(int paths, const int16_t* p2lut, int have_cost, int D)
    size_t csgm_scratch_bytes(int W, int D)
    size_t csgm_cost_work_bytes(int W)
    void csgm_pad_rows(const uint8_t* img, int H, int W, uint8_t* pad, int y0, int y1)
    void csgm_census_rows(const uint8_t* pad, int H, int W, uint32_t* out, int y0, int y1,
                          uint8_t* b0, uint8_t* b1, uint8_t* b2)
    void csgm_hamming_row(const uint32_t* cl, const uint32_t* cr, uint32_t* rev, uint16_t* out,
                          int W, int D, uint16_t invalid_cost)
    void csgm_wta_row(const uint16_t* S, float* out, int W, int D, double uniqueness, int subpixel)
    void csgm_right_row(const uint16_t* S, float* out, int W, int D, uint16_t* rbc, uint16_t* rbd)
    void csgm_lr_row(const float* dl, const float* dr, float* out, int W, double tol)
    void csgm_median_pad_row(const float* src, int H, int W, float* pad, int py)
    void csgm_median_row(const float* pad, int W, float* out, int y)
    ctypedef struct csgm_census_io:
        const uint8_t* gl
        const uint8_t* gr
        uint8_t* padl
        uint8_t* padr
        uint8_t* work
    ctypedef struct csgm_buffers:
        uint16_t* vf
        uint16_t* vb
        int* rowcnt
        uint8_t* scratch
        uint16_t* sout
        float* dl
        float* dr
        float* lr
        float* pad
        float* disp
        float* conf
    void csgm_sgm(const csgm_params* p, const uint16_t* cost, const uint8_t* g, const csgm_buffers* b,
                  const csgm_census_io* census, int nthreads)
    void csgm_cost(const csgm_census_io* io, int H, int W, int D, uint32_t* cl, uint32_t* cr, uint16_t* cost,
                   uint16_t invalid_cost, int nthreads)

#: True in the build compiled for x86-64-v3 (``_census_sgm_avx2``).
AVX2 = bool(csgm_build_avx2())


def scratch_bytes(int W, int D):
    """Bytes of SGM scratch per pass thread (two are used) for width ``W`` and ``D`` disparities."""
    return csgm_scratch_bytes(W, D)


def narrow_sums(int paths, const int16_t[::1] p2lut, bint volume):
    """Whether the SGM keeps its per-pass partial sums as uint8 (else uint16).

    True when the costs are the Hamming costs the passes compute (no cost ``volume``: at most 24) and
    ``paths / 2 * (24 + max(p2lut)) <= 255`` (a path cost is at most its matching cost plus P2).
    """
    return bool(csgm_narrow(paths, &p2lut[0], 1 if volume else 0))


def byte_path_costs(int paths, const int16_t[::1] p2lut, bint volume, int D):
    """Whether the SGM passes keep their path costs as uint8 too (32 disparities per AVX2 instruction).

    True in the AVX2 build with 8 paths, ``D`` a multiple of 16 and :func:`narrow_sums`; the same integers
    as the int16 path costs either way.
    """
    return bool(csgm_narrow8(paths, &p2lut[0], 1 if volume else 0, D))


def keyed_wta(int paths, const int16_t[::1] p2lut, bint volume, int D):
    """Whether the SGM stage's winner-takes-all (both views) runs on 16-bit keys ``(cost << 7) | d``.

    True in the AVX2 build with :func:`narrow_sums` (a pixel's full sum is then at most 510) and
    ``D <= 128``; the same disparities as the plain winner-takes-all either way.
    """
    return bool(csgm_packed(paths, &p2lut[0], 1 if volume else 0, D))


def cost_work_bytes(int W, int nthreads):
    """Bytes of census / Hamming scratch for ``nthreads`` threads at width ``W``."""
    return csgm_cost_work_bytes(W) * nthreads + 64


# ---------------------------------------------------------------- census ----
def census5x5(const uint8_t[:, ::1] img, uint32_t[:, ::1] out, int nthreads):
    """24-bit 5x5 census (bit = neighbour < centre, row-major, MSB first, edge clamp)."""
    cdef int H = img.shape[0], W = img.shape[1]
    cdef uint8_t[:, ::1] pad = np.empty((H + 4, W + 4), np.uint8)
    cdef uint8_t[:, ::1] work = np.empty((nthreads, 3 * W), np.uint8)
    cdef int t, tid, y0, y1
    with nogil:
        for t in prange(nthreads, schedule="static", num_threads=nthreads):
            csgm_pad_rows(&img[0, 0], H, W, &pad[0, 0], (H + 4) * t // nthreads,
                          (H + 4) * (t + 1) // nthreads)
        for t in prange(nthreads, schedule="static", num_threads=nthreads):
            tid = threadid()
            y0 = H * t // nthreads
            y1 = H * (t + 1) // nthreads
            csgm_census_rows(&pad[0, 0], H, W, &out[0, 0], y0, y1, &work[tid, 0], &work[tid, W],
                             &work[tid, 2 * W])


# --------------------------------------------------------------- hamming ----
def hamming_volume(const uint32_t[:, ::1] cl, const uint32_t[:, ::1] cr,
                   uint16_t[:, :, ::1] out, uint16_t invalid_cost, int nthreads):
    """out[y, x, d] = popcount(cl[y, x] ^ cr[y, x - d]); ``invalid_cost`` where x < d."""
    cdef int H = cl.shape[0], W = cl.shape[1], D = out.shape[2]
    cdef int y, tid
    cdef uint32_t[:, ::1] work = np.empty((nthreads, W), np.uint32)
    with nogil:
        for y in prange(H, schedule="static", num_threads=nthreads):
            tid = threadid()
            csgm_hamming_row(&cl[y, 0], &cr[y, 0], &work[tid, 0], &out[y, 0, 0], W, D, invalid_cost)


cdef csgm_census_io census_io(const uint8_t[:, ::1] gl, const uint8_t[:, ::1] gr, ws):
    """The census inputs: ``gl``, ``gr`` and the scratch ``ws.padl``, ``ws.padr``, ``ws.work`` (``ws`` holds them)."""
    cdef uint8_t[:, ::1] padl = ws.padl, padr = ws.padr
    cdef uint8_t[::1] work = ws.work
    cdef csgm_census_io io
    io.gl = &gl[0, 0]
    io.gr = &gr[0, 0]
    io.padl = &padl[0, 0]
    io.padr = &padr[0, 0]
    io.work = &work[0]
    return io


def cost_stage(ws, const uint8_t[:, ::1] gl, const uint8_t[:, ::1] gr, uint16_t[:, :, ::1] cost,
               uint16_t invalid_cost, int nthreads):
    """Census of both gray images (``ws.cl``, ``ws.cr``) and, unless ``cost`` is None, their Hamming volume ``cost``.

    One parallel region. ``ws``: the workspace (``census_sgm.SGMWorkspace``: ``padl``, ``padr``, (H + 4) x
    (W + 4) scratch; ``cl``, ``cr``; ``work``, :func:`cost_work_bytes` bytes).
    """
    cdef uint32_t[:, ::1] cl = ws.cl, cr = ws.cr
    cdef int H = gl.shape[0], W = gl.shape[1]
    cdef int D = 1
    cdef uint16_t* volume = NULL
    cdef csgm_census_io io = census_io(gl, gr, ws)
    if cost is not None:
        D = cost.shape[2]
        volume = &cost[0, 0, 0]
    with nogil:
        csgm_cost(&io, H, W, D, &cl[0, 0], &cr[0, 0], volume, invalid_cost, nthreads)


# ------------------------------------------------------------------- SGM ----
cdef struct StageParams:
    # filled from the dict of vpp_service.matchers.census_sgm.stage_params (one key per field)
    int paths               # 4 or 8
    int p1                  # P1 (P2 comes from the table p2lut)
    double uniqueness       # WTA uniqueness ratio
    int subpixel            # parabola refinement
    int lr_check            # right WTA and left-right check
    double tolerance        # of the left-right check
    int median              # 3x3 median
    int border_margin       # border.reject_border_matches (0 = off)
    int gap_size            # holes.fill_short_gaps (0 = off) with gap_step
    double gap_step
    double conf_peak        # confidence: the peak-ratio margin that counts as sure
    int wta                 # 0: stop after the aggregation (benchmarks)


cdef csgm_params make_params(int H, int W, int D, int paths, int P1, const int16_t[::1] p2lut):
    """The C parameters of an aggregation over ``paths`` paths (no WTA step set; csgm_sgm sets the rest)."""
    cdef csgm_params p
    p.H = H
    p.W = W
    p.D = D
    p.paths = paths
    p.P1 = P1
    p.p2lut = &p2lut[0]
    p.uniqueness = 1.0
    p.subpixel = 0
    p.lr_check = 0
    p.median = 0
    p.tolerance = 0.0
    p.cl = NULL
    p.cr = NULL
    p.narrow = 0  # csgm_sgm decides
    p.narrow8 = 0
    p.packed = 0
    p.border_margin = 0
    p.gap_size = 0
    p.gap_step = 0.0
    p.conf_peak = 1.0
    return p


cdef csgm_buffers buffers(uint16_t[:, :, ::1] vf, uint16_t[:, :, ::1] vb, int[::1] rowcnt, uint8_t[::1] scratch):
    """The aggregation's buffers (partial sums, row counters, scratch); no output set."""
    cdef csgm_buffers b
    b.vf = &vf[0, 0, 0]
    b.vb = &vb[0, 0, 0]
    b.rowcnt = &rowcnt[0]
    b.scratch = &scratch[0]
    b.sout = NULL
    b.dl = NULL
    b.dr = NULL
    b.lr = NULL
    b.pad = NULL
    b.disp = NULL
    b.conf = NULL
    return b


def aggregate(const uint16_t[:, :, ::1] C, const uint8_t[:, ::1] g,
              uint16_t[:, :, ::1] S, int paths, int P1,
              const int16_t[::1] p2lut, int nthreads):
    """S = sum over 4 or 8 SGM paths of L_r (65535 where x < d). Costs <= 4095, P1, P2 <= 4095."""
    cdef int H = C.shape[0], W = C.shape[1], D = C.shape[2]
    cdef csgm_params p = make_params(H, W, D, paths, P1, p2lut)
    cdef uint16_t[:, :, ::1] vf = np.empty((H, W, D), np.uint16)
    cdef int two = nthreads > 1  # the backward pass's partial sums (second thread)
    cdef uint16_t[:, :, ::1] vb = np.empty((H if two else 1, W if two else 1, D if two else 1), np.uint16)
    cdef int[::1] rowcnt = np.empty(H, np.intc)
    cdef uint8_t[::1] scratch = np.empty(2 * csgm_scratch_bytes(W, D) + 64, np.uint8)
    cdef csgm_buffers b = buffers(vf, vb, rowcnt, scratch)
    b.sout = &S[0, 0, 0]
    with nogil:
        csgm_sgm(&p, &C[0, 0, 0], &g[0, 0], &b, NULL, nthreads)


def sgm_stage(dict params, const int16_t[::1] p2lut, ws, const uint16_t[:, :, ::1] cost,
              const uint8_t[:, ::1] gl, const uint8_t[:, ::1] gr, float[:, ::1] out, int nthreads,
              float[:, ::1] conf=None):
    """(Census,) aggregation, left and right WTA, left-right check and median in one parallel region.

    ``params``: the settings (the dict of ``census_sgm.stage_params``, converted to the ``StageParams``
    struct above); ``p2lut``: the 256 P2 of ``census_sgm.p2_table``; ``ws``: the buffers
    (``census_sgm.SGMWorkspace`` of H x W images and D disparities: ``vf``, ``vb`` H x W x D partial sums,
    ``vb`` only read with >= 2 threads; ``rowcnt``: H ints; ``scratch``: 2 x :func:`scratch_bytes` + 64
    bytes; ``dl``, ``dr``, ``lr``: H x W; ``mpad``: (H + 2) x (W + 2); ``cl``, ``cr``, ``padl``, ``padr``,
    ``work`` as for :func:`cost_stage`).

    The costs are the volume ``cost`` (H x W x D), else (None) each pass computes them row by row from the
    census codes ``ws.cl``, ``ws.cr``. With ``gr`` (not None) the region first computes those codes of
    ``gl`` and ``gr`` (the left and right gray images), so a call without guided stereo is one parallel
    region; ``gl`` also gives the adaptive P2. The final disparity goes to ``out`` (H x W float32); the
    left WTA and the left-right check write to ``ws.dl``, ``ws.lr`` when a later step reads them, else
    straight to ``out``. ``wta`` False stops after the aggregation (benchmarks time the stage so).
    ``border_margin`` and ``gap_size``, ``gap_step`` (0 = off) run ``border.reject_border_matches`` and
    ``holes.fill_short_gaps`` (``_gaps.h``) on each row right after its left-right check, before the median.
    ``conf`` (H x W float32, or None: not computed, no cost) gets each pixel's confidence in [0, 1] from
    its best disparity ``b`` (lowest cost, lowest ``d`` on ties; before the uniqueness test): the peak ratio
    ``min(1, (1 - S_best / S_second) / conf_peak)`` (``S_second`` the lowest cost with ``|d - b| > 1``; 0
    without one or when it is 0) times ``max(0, 1 - |b - d_R(x - b)| / (tolerance + 1))`` (``d_R`` the right
    view's integer WTA, computed for it even without the left-right check). The disparity is the same
    either way.
    """
    cdef StageParams s = params
    cdef uint16_t[:, :, ::1] vf = ws.vf, vb = ws.vb
    cdef int[::1] rowcnt = ws.rowcnt
    cdef uint8_t[::1] scratch = ws.scratch
    cdef float[:, ::1] dr = ws.dr, pad = ws.mpad
    cdef float[:, ::1] dl = out, lr = out  # the left WTA, the checked map: out when no later step reads them
    cdef uint32_t[:, ::1] cl, cr
    cdef int H = gl.shape[0], W = gl.shape[1], D = vf.shape[2]
    cdef csgm_params p = make_params(H, W, D, s.paths, s.p1, p2lut)
    cdef csgm_buffers b = buffers(vf, vb, rowcnt, scratch)
    cdef csgm_census_io io
    cdef const csgm_census_io* census = NULL
    cdef const uint16_t* volume = NULL
    if s.median:
        lr = ws.lr
    if s.median or s.lr_check:
        dl = ws.dl
    if s.wta:
        b.dl = &dl[0, 0]
    b.dr = &dr[0, 0]
    b.lr = &lr[0, 0]
    b.pad = &pad[0, 0]
    b.disp = &out[0, 0]
    p.uniqueness = s.uniqueness
    p.subpixel = 1 if s.subpixel else 0
    p.lr_check = 1 if s.lr_check else 0
    p.median = 1 if s.median else 0
    p.tolerance = s.tolerance
    p.border_margin = s.border_margin
    p.gap_size = s.gap_size
    p.gap_step = s.gap_step
    p.conf_peak = s.conf_peak
    if conf is not None:
        b.conf = &conf[0, 0]
    if cost is not None:
        volume = &cost[0, 0, 0]
    else:
        cl = ws.cl
        cr = ws.cr
        p.cl = &cl[0, 0]
        p.cr = &cr[0, 0]
    if gr is not None:
        io = census_io(gl, gr, ws)
        census = &io
    with nogil:
        csgm_sgm(&p, volume, &gl[0, 0], &b, census, nthreads)


# ------------------------------------------------------------------- WTA ----
def winner_takes_all(const uint16_t[:, :, ::1] S, float[:, ::1] out,
                     double uniqueness, bint subpixel, int nthreads):
    """Lowest-cost disparity per pixel (over d <= x) with uniqueness test and parabola refinement."""
    cdef int H = S.shape[0], W = S.shape[1], D = S.shape[2]
    cdef int y
    cdef int sp = 1 if subpixel else 0
    with nogil:
        for y in prange(H, schedule="static", num_threads=nthreads):
            csgm_wta_row(&S[y, 0, 0], &out[y, 0], W, D, uniqueness, sp)


def right_disparity(const uint16_t[:, :, ::1] S, float[:, ::1] out, int nthreads):
    """out[y, xr] = argmin_d S[y, xr + d, d] over xr + d < W (first minimum)."""
    cdef int H = S.shape[0], W = S.shape[1], D = S.shape[2]
    cdef int y, tid
    cdef uint16_t[:, ::1] work = np.empty((nthreads, 2 * W), np.uint16)
    with nogil:
        for y in prange(H, schedule="static", num_threads=nthreads):
            tid = threadid()
            csgm_right_row(&S[y, 0, 0], &out[y, 0], W, D, &work[tid, 0], &work[tid, W])


def left_right_check(const float[:, ::1] dl, const float[:, ::1] dr, float[:, ::1] out,
                     double tolerance, int nthreads):
    """out = dl where |dl(x) - dr(x - round(dl(x)))| <= tolerance, else NaN."""
    cdef int H = dl.shape[0], W = dl.shape[1]
    cdef int y
    with nogil:
        for y in prange(H, schedule="static", num_threads=nthreads):
            csgm_lr_row(&dl[y, 0], &dr[y, 0], &out[y, 0], W, tolerance)


# ---------------------------------------------------------------- median ----
def median3x3(const float[:, ::1] src, float[:, ::1] out, int nthreads):
    """3x3 median over the valid (non-NaN) neighbours of each valid pixel; NaN stays NaN."""
    cdef int H = src.shape[0], W = src.shape[1]
    cdef float[:, ::1] pad = np.empty((H + 2, W + 2), np.float32)
    cdef int t, y
    with nogil:
        for t in prange(nthreads, schedule="static", num_threads=nthreads):
            for y in range((H + 2) * t // nthreads, (H + 2) * (t + 1) // nthreads):
                csgm_median_pad_row(&src[0, 0], H, W, &pad[0, 0], y)
        for y in prange(H, schedule="static", num_threads=nthreads):
            csgm_median_row(&pad[0, 0], W, &out[0, 0], y)
