"""Guided-stereo cost modulation kernel (Poggi et al., CVPR 2019).

Unchecked; :func:`vpp_service.matchers.guided.modulate_cost` validates the
arguments and chooses the output array. Only pixels with a valid hint
(finite, > 0) are touched; the others keep their cost.
"""
from cython.parallel cimport prange
from libc.stdint cimport uint8_t, uint16_t
from libc.math cimport exp, floor, isnan

ctypedef fused cost_t:
    uint8_t
    uint16_t
    float


cdef inline void modulate_pixel(cost_t* p, int D, double h, double k, double inv2c2,
                                double maxval) noexcept nogil:
    cdef int d
    cdef double v, dd
    for d in range(D):
        dd = <double>d - h
        v = <double>p[d] * (k * (1.0 - exp(-(dd * dd) * inv2c2)))
        if cost_t is float:
            p[d] = <float>v
        else:
            v = floor(v + 0.5)
            if v > maxval:
                v = maxval
            p[d] = <cost_t>v


def modulate(cost_t[:, :, ::1] cost, const float[:, ::1] hints, double k, double c,
             int nthreads):
    """In place: cost(y, x, d) *= k (1 - exp(-(d - h)^2 / 2c^2)) where h = hints[y, x] > 0.

    Integer volumes are rounded half up and saturated at the dtype maximum.
    """
    cdef int H = cost.shape[0], W = cost.shape[1], D = cost.shape[2]
    cdef int y, x
    cdef float h
    cdef double inv2c2 = 1.0 / (2.0 * c * c)
    cdef double maxval
    if cost_t is uint8_t:
        maxval = 255.0
    elif cost_t is uint16_t:
        maxval = 65535.0
    else:
        maxval = 0.0
    with nogil:
        for y in prange(H, schedule="dynamic", num_threads=nthreads):
            for x in range(W):
                h = hints[y, x]
                if isnan(h) or not (h > 0):
                    continue
                modulate_pixel(&cost[y, x, 0], D, <double>h, k, inv2c2, maxval)
