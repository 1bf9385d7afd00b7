"""Speckle filter kernel (nogil, typed memoryviews; the C is in ``_speckle.h``, with ``_omp_team.h``).

Unchecked; :func:`vpp_service.matchers.speckle.remove_speckles` validates the
arguments and allocates the output and scratch. Call that, not this.
"""
from libc.stdint cimport int32_t


cdef extern from "_speckle.h" nogil:
    int spk_filter(const float* src, float* dst, int H, int W, int32_t* q, int32_t* parent, int32_t* count,
                   int max_size, int max_diff16, int nthreads)


def speckle_filter(const float[:, ::1] src, float[:, ::1] dst, int32_t[::1] scratch, int max_size,
                   int max_diff16, int nthreads):
    """dst = src with every component of <= max_size pixels NaN; scratch: 3 * H * W int32.

    Returns False (dst then undefined) when a finite value is at or beyond 32767 / 16 in magnitude.
    """
    cdef int H = src.shape[0], W = src.shape[1]
    cdef long n = <long>H * W
    cdef int bad
    with nogil:
        bad = spk_filter(&src[0, 0], &dst[0, 0], H, W, &scratch[0], &scratch[n], &scratch[2 * n], max_size,
                         max_diff16, nthreads)
    return not bad
