"""See-through filter kernel (unchecked; see ``see_through.filter_see_through``)."""


cdef extern from "_see_through.h" nogil:
    long vpp_see_through(const float* src, float* dst, int H, int W, int rx, int ry, float margin,
                         float min_gap)


def see_through_rows(const float[:, ::1] src, float[:, ::1] dst, int rx, int ry, float margin,
                     float min_gap):
    """Copy ``src`` into ``dst`` (points only, NaN elsewhere) without the see-through points.

    A point of disparity d is dropped when the (2 rx + 1) x (2 ry + 1) window around it,
    clipped at the borders, holds values > max(d (1 + margin), d + min_gap) both left and
    right of it, or both above and below it. Returns the number of dropped points (-1 when
    the buffers cannot be allocated).
    """
    cdef int H = src.shape[0], W = src.shape[1]
    cdef long dropped
    with nogil:
        dropped = vpp_see_through(&src[0, 0], &dst[0, 0], H, W, rx, ry, margin, min_gap)
    return dropped
