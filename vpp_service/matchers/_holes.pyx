"""Row-wise background hole filling kernel (unchecked; see ``holes.fill_holes``)."""
from cython.parallel cimport prange
from libc.math cimport isnan


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
