"""Row-wise hole filling kernels (unchecked; see ``holes.fill_holes`` and ``holes.fill_short_gaps``)."""
from cython.parallel cimport prange
from libc.math cimport isnan


cdef extern from "_gaps.h" nogil:
    void vpp_gap_row(const float* src, float* dst, int W, int max_gap, double max_step)


cdef inline void fill_row(const float* src, float* dst, int W, float empty) noexcept nogil:
    cdef int x, left = -1, right, j
    cdef float v
    x = 0
    while x < W:
        if not isnan(src[x]):
            dst[x] = src[x]
            left = x
            x += 1
            continue
        right = x
        while right < W and isnan(src[right]):
            right += 1
        # hole spans [x, right); neighbours at left (or -1) and right (or W)
        if left < 0 and right >= W:
            v = empty
        elif left < 0:
            v = src[right]
        elif right >= W:
            v = src[left]
        else:
            v = src[left] if src[left] < src[right] else src[right]
        for j in range(x, right):
            dst[j] = v
        x = right


def fill_rows(const float[:, ::1] src, float[:, ::1] dst, float empty, int nthreads):
    """Each NaN run takes min(nearest valid left, nearest valid right) on its row."""
    cdef int H = src.shape[0], W = src.shape[1]
    cdef int y
    with nogil:
        for y in prange(H, schedule="static", num_threads=nthreads):
            fill_row(&src[y, 0], &dst[y, 0], W, empty)


def fill_gap_rows(const float[:, ::1] src, float[:, ::1] dst, int max_gap, double max_step,
                  int nthreads):
    """Interior NaN runs of <= max_gap pixels: linear between the ends if they differ
    by <= max_step, else the smaller end; everything else copied."""
    cdef int H = src.shape[0], W = src.shape[1]
    cdef int y
    with nogil:
        for y in prange(H, schedule="static", num_threads=nthreads):
            vpp_gap_row(&src[y, 0], &dst[y, 0], W, max_gap, max_step)
