"""Census-SGM kernels (nogil, typed memoryviews, OpenMP).

Low-level, unchecked kernels behind :mod:`vpp_service.matchers.census_sgm`;
the Python wrappers there validate every argument (shape, dtype, contiguity)
and allocate the outputs. Call those, not these.

Conventions
-----------
* cost / aggregated volumes are C-contiguous ``H x W x D`` uint16, ``d``
  fastest, disparity ``d`` matching left ``x`` with right ``x - d``;
* path costs are kept as int16 in row / column buffers padded with one
  sentinel on each side of the disparity axis, so the inner ``d`` loop has no
  branch and vectorises;
* every routine takes ``nthreads`` (>= 1) for its ``prange``.
"""
from cython.parallel cimport prange, threadid
from libc.stdint cimport uint8_t, uint16_t, int16_t, uint32_t
from libc.stdlib cimport malloc, free
from libc.math cimport floor, isnan, NAN, fabs

# Sentinel stored left of d = 0 and right of d = D - 1 in path buffers. Any
# path cost is <= COST_CAP + P2 <= 8190 < SENTINEL, and SENTINEL + P1 fits int16.
cdef enum:
    SENTINEL = 16383


cdef inline int popcount32(uint32_t v) noexcept nogil:
    v = v - ((v >> 1) & <uint32_t>0x55555555)
    v = (v & <uint32_t>0x33333333) + ((v >> 2) & <uint32_t>0x33333333)
    v = (v + (v >> 4)) & <uint32_t>0x0F0F0F0F
    v = v + (v >> 8)
    v = v + (v >> 16)
    return <int>(v & 0x3F)  # shifts, not a multiply: vectorises on plain SSE2


cdef inline int clampi(int v, int lo, int hi) noexcept nogil:
    if v < lo:
        return lo
    if v > hi:
        return hi
    return v


# ---------------------------------------------------------------- census ----
cdef inline uint32_t census_pixel(const uint8_t[:, ::1] img, int y, int x,
                                  int H, int W) noexcept nogil:
    cdef uint32_t code = 0
    cdef int dy, dx, yy, xx
    cdef uint8_t c = img[y, x]
    for dy in range(-2, 3):
        yy = clampi(y + dy, 0, H - 1)
        for dx in range(-2, 3):
            if dy == 0 and dx == 0:
                continue
            xx = clampi(x + dx, 0, W - 1)
            code = (code << 1) | (<uint32_t>(img[yy, xx] < c))
    return code


def census5x5(const uint8_t[:, ::1] img, uint32_t[:, ::1] out, int nthreads):
    """24-bit 5x5 census (bit = neighbour < centre, row-major, MSB first, edge clamp)."""
    cdef int H = img.shape[0], W = img.shape[1]
    cdef int y, x
    with nogil:
        for y in prange(H, schedule="static", num_threads=nthreads):
            for x in range(W):
                out[y, x] = census_pixel(img, y, x, H, W)


# --------------------------------------------------------------- hamming ----
cdef inline void hamming_row(const uint32_t* cl, const uint32_t* cr, uint32_t* rev,
                             uint16_t* out, int W, int D, uint16_t invalid_cost) noexcept nogil:
    """One row; ``rev`` (W entries) receives cr reversed so the d loop reads forwards
    (SSE2 has no reversed loads, a forward loop vectorises)."""
    cdef int x, d, dmax
    cdef uint32_t a
    cdef uint16_t* p
    cdef const uint32_t* q
    for x in range(W):
        rev[x] = cr[W - 1 - x]
    for x in range(W):
        p = out + <Py_ssize_t>x * D
        a = cl[x]
        q = rev + (W - 1 - x)  # q[d] == cr[x - d]
        dmax = x if x < D - 1 else D - 1
        for d in range(dmax + 1):
            p[d] = <uint16_t>popcount32(a ^ q[d])
        for d in range(dmax + 1, D):
            p[d] = invalid_cost


def hamming_volume(const uint32_t[:, ::1] cl, const uint32_t[:, ::1] cr,
                   uint16_t[:, :, ::1] out, uint16_t invalid_cost, int nthreads):
    """out[y, x, d] = popcount(cl[y, x] ^ cr[y, x - d]); ``invalid_cost`` where x < d."""
    cdef int H = cl.shape[0], W = cl.shape[1], D = out.shape[2]
    cdef int y, tid
    cdef uint32_t* work = <uint32_t*>malloc(<Py_ssize_t>nthreads * W * sizeof(uint32_t))
    if work == NULL:
        raise MemoryError("census-sgm: cannot allocate the Hamming buffers")
    with nogil:
        for y in prange(H, schedule="static", num_threads=nthreads):
            tid = threadid()
            hamming_row(&cl[y, 0], &cr[y, 0], work + <Py_ssize_t>tid * W, &out[y, 0, 0],
                        W, D, invalid_cost)
    free(work)


# ------------------------------------------------------------------- SGM ----
cdef inline int16_t path_start(const uint16_t* C, int16_t* cur, int D) noexcept nogil:
    """First pixel of a path: L = C. Returns min_d L."""
    cdef int d
    cdef int16_t m = SENTINEL, v
    for d in range(D):
        v = <int16_t>C[d]
        cur[d] = v
        if v < m:
            m = v
    return m


cdef inline int16_t path_step(const uint16_t* C, const int16_t* prev, int16_t pm,
                              int16_t* cur, int D, int16_t P1, int16_t P2) noexcept nogil:
    """L(p,d) = C(p,d) + min(L'(d), L'(d-1)+P1, L'(d+1)+P1, min L' + P2) - min L'.

    ``prev`` and ``cur`` point at element 0 of buffers padded with a sentinel
    at index -1 and D. Returns min_d L(p, d).
    """
    cdef int d
    cdef int16_t v, t, m = SENTINEL
    cdef int16_t jump = pm + P2
    for d in range(D):
        v = prev[d]
        t = prev[d - 1] + P1
        if t < v:
            v = t
        t = prev[d + 1] + P1
        if t < v:
            v = t
        if jump < v:
            v = jump
        v = <int16_t>(C[d] + v - pm)
        cur[d] = v
        if v < m:
            m = v
    return m


cdef inline void store_row(uint16_t* S, const int16_t* L, int D) noexcept nogil:
    cdef int d
    for d in range(D):
        S[d] = <uint16_t>L[d]


cdef inline void add_row(uint16_t* S, const int16_t* L, int D) noexcept nogil:
    cdef int d
    for d in range(D):
        S[d] = <uint16_t>(S[d] + <uint16_t>L[d])


cdef inline void fill_sentinels(int16_t* buf, int n_pixels, int stride) noexcept nogil:
    """Set index 0 and stride-1 of each of the n_pixels padded slots to SENTINEL."""
    cdef int i
    for i in range(n_pixels):
        buf[<Py_ssize_t>i * stride] = SENTINEL
        buf[<Py_ssize_t>i * stride + stride - 1] = SENTINEL


cdef inline int absdiff(int a, int b) noexcept nogil:
    return a - b if a > b else b - a


cdef void horizontal_row(const uint16_t* C, const uint8_t* g, uint16_t* S,
                         int W, int D, int16_t P1, const int16_t* p2lut,
                         int16_t* bufa, int16_t* bufb) noexcept nogil:
    """Left->right path (stored into S) then right->left path (added to S)."""
    cdef int x
    cdef int16_t pm
    cdef int16_t* prev = bufa + 1
    cdef int16_t* cur = bufb + 1
    cdef int16_t* tmp
    pm = path_start(C, prev, D)
    store_row(S, prev, D)
    for x in range(1, W):
        pm = path_step(C + <Py_ssize_t>x * D, prev, pm, cur, D, P1,
                       p2lut[absdiff(g[x], g[x - 1])])
        store_row(S + <Py_ssize_t>x * D, cur, D)
        tmp = prev
        prev = cur
        cur = tmp
    pm = path_start(C + <Py_ssize_t>(W - 1) * D, prev, D)
    add_row(S + <Py_ssize_t>(W - 1) * D, prev, D)
    for x in range(W - 2, -1, -1):
        pm = path_step(C + <Py_ssize_t>x * D, prev, pm, cur, D, P1,
                       p2lut[absdiff(g[x], g[x + 1])])
        add_row(S + <Py_ssize_t>x * D, cur, D)
        tmp = prev
        prev = cur
        cur = tmp


cdef void vertical_pixel(const uint16_t* C, uint16_t* S, const uint8_t* g_row,
                         const uint8_t* g_prev_row, int x, int W, int D, int stride,
                         int first_row, int ndirs, int16_t P1, const int16_t* p2lut,
                         int16_t* prev_buf, int16_t* prev_min,
                         int16_t* cur_buf, int16_t* cur_min) noexcept nogil:
    """One pixel of the 1 (vertical) or 3 (diagonal, vertical, diagonal) row-to-row paths.

    Direction k uses the previous-row pixel x + dx with dx = (0,) or (-1, 0, 1).
    Buffers are laid out [k][x][stride] with stride = D + 2 (padded).
    """
    cdef int k, dx, xp
    cdef int16_t* cur
    cdef Py_ssize_t plane = <Py_ssize_t>W * stride
    for k in range(ndirs):
        dx = 0 if ndirs == 1 else k - 1
        xp = x + dx
        cur = cur_buf + k * plane + <Py_ssize_t>x * stride + 1
        if first_row or xp < 0 or xp >= W:
            cur_min[k * W + x] = path_start(C, cur, D)
        else:
            cur_min[k * W + x] = path_step(
                C, prev_buf + k * plane + <Py_ssize_t>xp * stride + 1,
                prev_min[k * W + xp], cur, D, P1,
                p2lut[absdiff(g_row[x], g_prev_row[xp])])
        add_row(S, cur, D)


cdef int vertical_pass(const uint16_t[:, :, ::1] C, const uint8_t[:, ::1] g,
                       uint16_t[:, :, ::1] S, int ndirs, int downward, int16_t P1,
                       const int16_t* p2lut, int nthreads) noexcept nogil:
    """Top-down (``downward``) or bottom-up row-to-row paths added to S; -1 if out of memory."""
    cdef int H = C.shape[0], W = C.shape[1], D = C.shape[2]
    cdef int stride = D + 2
    cdef Py_ssize_t n = <Py_ssize_t>ndirs * W * stride
    cdef int16_t* bufa = <int16_t*>malloc(n * sizeof(int16_t))
    cdef int16_t* bufb = <int16_t*>malloc(n * sizeof(int16_t))
    cdef int16_t* mina = <int16_t*>malloc(ndirs * W * sizeof(int16_t))
    cdef int16_t* minb = <int16_t*>malloc(ndirs * W * sizeof(int16_t))
    cdef int16_t* tmp
    cdef int i, y, x, yp, first
    if bufa == NULL or bufb == NULL or mina == NULL or minb == NULL:
        free(bufa)
        free(bufb)
        free(mina)
        free(minb)
        return -1
    fill_sentinels(bufa, ndirs * W, stride)
    fill_sentinels(bufb, ndirs * W, stride)
    for i in range(H):
        y = i if downward else H - 1 - i
        yp = y - 1 if downward else y + 1
        first = 1 if i == 0 else 0
        if first:
            yp = y
        for x in prange(W, schedule="static", num_threads=nthreads):
            vertical_pixel(&C[y, x, 0], &S[y, x, 0], &g[y, 0], &g[yp, 0], x, W, D,
                           stride, first, ndirs, P1, p2lut, bufa, mina, bufb, minb)
        tmp = bufa
        bufa = bufb
        bufb = tmp
        tmp = mina
        mina = minb
        minb = tmp
    free(bufa)
    free(bufb)
    free(mina)
    free(minb)
    return 0


def aggregate(const uint16_t[:, :, ::1] C, const uint8_t[:, ::1] g,
              uint16_t[:, :, ::1] S, int paths, int P1,
              const int16_t[::1] p2lut, int nthreads):
    """S = sum over 4 or 8 SGM paths of L_r. Costs must be <= 4095, P1, P2 <= 4095."""
    cdef int H = C.shape[0], W = C.shape[1], D = C.shape[2]
    cdef int y, tid, stride = D + 2
    cdef int16_t* bufs = <int16_t*>malloc(<Py_ssize_t>nthreads * 2 * stride * sizeof(int16_t))
    cdef int16_t p1 = <int16_t>P1
    cdef const int16_t* lut = &p2lut[0]
    cdef int ndirs = 3 if paths == 8 else 1
    cdef int failed = 0
    if bufs == NULL:
        raise MemoryError("census-sgm: cannot allocate the SGM path buffers")
    with nogil:
        fill_sentinels(bufs, 2 * nthreads, stride)
        for y in prange(H, schedule="static", num_threads=nthreads):
            tid = threadid()
            horizontal_row(&C[y, 0, 0], &g[y, 0], &S[y, 0, 0], W, D, p1, lut,
                           bufs + 2 * tid * stride, bufs + (2 * tid + 1) * stride)
        free(bufs)
        if vertical_pass(C, g, S, ndirs, 1, p1, lut, nthreads) != 0:
            failed = 1
        elif vertical_pass(C, g, S, ndirs, 0, p1, lut, nthreads) != 0:
            failed = 1
    if failed:
        raise MemoryError("census-sgm: cannot allocate the SGM path buffers")


# ------------------------------------------------------------------- WTA ----
cdef inline float wta_pixel(const uint16_t* p, int D, double uniqueness,
                            int subpixel) noexcept nogil:
    cdef int d, best = 0
    cdef int bv = p[0], second = 1 << 30, c0, c2, denom
    for d in range(1, D):
        if p[d] < bv:
            bv = p[d]
            best = d
    for d in range(D):
        if (d < best - 1 or d > best + 1) and p[d] < second:
            second = p[d]
    if second != (1 << 30) and not (<double>bv < uniqueness * <double>second):
        return NAN
    if subpixel and 0 < best < D - 1:
        c0 = p[best - 1]
        c2 = p[best + 1]
        denom = c0 - 2 * bv + c2
        if denom > 0:
            return <float>(<double>best + <double>(c0 - c2) / (2.0 * <double>denom))
    return <float>best


def winner_takes_all(const uint16_t[:, :, ::1] S, float[:, ::1] out,
                     double uniqueness, bint subpixel, int nthreads):
    """Lowest-cost disparity per pixel with uniqueness test and parabola refinement."""
    cdef int H = S.shape[0], W = S.shape[1], D = S.shape[2]
    cdef int y, x
    cdef int sp = 1 if subpixel else 0
    with nogil:
        for y in prange(H, schedule="static", num_threads=nthreads):
            for x in range(W):
                out[y, x] = wta_pixel(&S[y, x, 0], D, uniqueness, sp)


cdef void right_row(const uint16_t* S, float* out, int* best_cost, int W,
                    int D) noexcept nogil:
    """Right WTA of one row, scanning the left volume in memory order.

    Candidates of right pixel xr come from x = xr + d, visited with increasing
    d, so the strict ``<`` keeps the lowest d on ties.
    """
    cdef int x, d, dmax, xr
    cdef int c
    cdef const uint16_t* p
    for x in range(W):
        best_cost[x] = 1 << 30
        out[x] = 0
    for x in range(W):
        p = S + <Py_ssize_t>x * D
        dmax = x if x < D - 1 else D - 1
        for d in range(dmax + 1):
            xr = x - d
            c = p[d]
            if c < best_cost[xr]:
                best_cost[xr] = c
                out[xr] = <float>d


def right_disparity(const uint16_t[:, :, ::1] S, float[:, ::1] out, int nthreads):
    """out[y, xr] = argmin_d S[y, xr + d, d] over xr + d < W (first minimum)."""
    cdef int H = S.shape[0], W = S.shape[1], D = S.shape[2]
    cdef int y, tid
    cdef int* work = <int*>malloc(<Py_ssize_t>nthreads * W * sizeof(int))
    if work == NULL:
        raise MemoryError("census-sgm: cannot allocate the right-WTA buffers")
    with nogil:
        for y in prange(H, schedule="static", num_threads=nthreads):
            tid = threadid()
            right_row(&S[y, 0, 0], &out[y, 0], work + <Py_ssize_t>tid * W, W, D)
    free(work)


def left_right_check(const float[:, ::1] dl, const float[:, ::1] dr, float[:, ::1] out,
                     double tolerance, int nthreads):
    """out = dl where |dl(x) - dr(x - round(dl(x)))| <= tolerance, else NaN."""
    cdef int H = dl.shape[0], W = dl.shape[1]
    cdef int y, x, xr
    cdef float d
    with nogil:
        for y in prange(H, schedule="static", num_threads=nthreads):
            for x in range(W):
                d = dl[y, x]
                out[y, x] = NAN
                if isnan(d):
                    continue
                xr = x - <int>floor(<double>d + 0.5)
                if xr < 0 or xr >= W or isnan(dr[y, xr]):
                    continue
                if fabs(<double>d - <double>dr[y, xr]) <= tolerance:
                    out[y, x] = d


# ---------------------------------------------------------------- median ----
cdef inline float median_pixel(const float[:, ::1] src, int y, int x, int H,
                               int W) noexcept nogil:
    cdef float vals[9]
    cdef float v
    cdef int n = 0, j, yy, xx
    for yy in range(y - 1, y + 2):
        if yy < 0 or yy >= H:
            continue
        for xx in range(x - 1, x + 2):
            if xx < 0 or xx >= W:
                continue
            v = src[yy, xx]
            if isnan(v):
                continue
            j = n
            while j > 0 and vals[j - 1] > v:
                vals[j] = vals[j - 1]
                j -= 1
            vals[j] = v
            n += 1
    if n % 2 == 1:
        return vals[n // 2]
    return (vals[n // 2 - 1] + vals[n // 2]) * 0.5


def median3x3(const float[:, ::1] src, float[:, ::1] out, int nthreads):
    """3x3 median over the valid (non-NaN) neighbours of each valid pixel; NaN stays NaN."""
    cdef int H = src.shape[0], W = src.shape[1]
    cdef int y, x
    with nogil:
        for y in prange(H, schedule="static", num_threads=nthreads):
            for x in range(W):
                if isnan(src[y, x]):
                    out[y, x] = NAN
                else:
                    out[y, x] = median_pixel(src, y, x, H, W)
