# Sparse wire points -> dense float32 maps, validated and scattered in one pass.
# The typed wrapper is vpp_service.transport.wire.points_to_maps; the literal NumPy
# version it must equal is tests/test_transport_points.py::reference_maps.
from libc.math cimport NAN, isfinite, isnan, nearbyint
from libc.stdint cimport int64_t

cdef enum:
    _BAD_UV = 1       # a coordinate is NaN or infinite
    _OUTSIDE = 2      # a (finite) point lies outside the image
    _BAD_VALUE = 4    # a value is NaN, infinite or <= 0

#: Bits of the returned problem mask (several may be set).
BAD_UV = _BAD_UV
OUTSIDE = _OUTSIDE
BAD_VALUE = _BAD_VALUE


def scatter_points(const float[::1] uv, const float[::1] vals, bint keep_min,
                   float[:, ::1] out, float[:, ::1] out_d, double fb, double doffs):
    """Validate ``n`` points and scatter them into ``out`` (pre-filled with NaN).

    ``uv`` holds ``x0, y0, x1, y1, ...`` (length ``2 n``), ``vals`` the ``n``
    values.  A point lands on pixel ``(rint(y), rint(x))`` (round half to
    even, as ``numpy.rint``); where several land on one pixel the smallest
    (``keep_min``) or the largest value wins.  When ``out_d`` has rows
    (metric points with a calibration) it receives the disparity
    ``fb / z - doffs`` (float64, stored as float32) of each winning depth
    ``z``, or stays NaN where that disparity is ``<= 0``; pass a 0 x 0 array
    otherwise.  ``out`` may be 0 x 0 when ``out_d`` has rows (``keep_min``):
    only the disparity map is filled, the largest disparity winning a pixel
    (the same values: the disparity falls as the depth grows).

    Returns the problem mask (``BAD_UV | OUTSIDE | BAD_VALUE``, 0 = valid);
    with a non-zero mask the maps hold partial results and must be dropped.
    """
    cdef Py_ssize_t n = vals.shape[0], i
    cdef bint with_z = out.shape[0] > 0
    cdef bint with_d = out_d.shape[0] > 0
    cdef int h = out.shape[0] if with_z else out_d.shape[0]
    cdef int w = out.shape[1] if with_z else out_d.shape[1]
    cdef float x, y, v, old, fd
    cdef float xlo = -0.5, xhi = <float>(w - 0.5), yhi = <float>(h - 0.5)
    cdef int bad = 0
    cdef int64_t r, c
    cdef double d
    if uv.shape[0] != 2 * n:
        raise ValueError(f"uv has {uv.shape[0]} values, need {2 * n}")
    if with_d and (out_d.shape[0] != h or out_d.shape[1] != w):
        raise ValueError("out_d must be 0 x 0 or the shape of out")
    if not with_z and not (with_d and keep_min):
        raise ValueError("out may be 0 x 0 only with an out_d (metric points, keep_min)")
    with nogil:
        for i in range(n):
            x = uv[2 * i]
            y = uv[2 * i + 1]
            v = vals[i]
            if not (isfinite(x) and isfinite(y)):
                bad |= _BAD_UV
                continue
            if x < xlo or x >= xhi or y < xlo or y >= yhi:
                bad |= _OUTSIDE
                continue
            if not (isfinite(v) and v > 0):
                bad |= _BAD_VALUE
                continue
            if bad:
                continue        # keep validating, stop writing
            r = <int64_t>nearbyint(y)
            c = <int64_t>nearbyint(x)
            if not with_z:      # disparity only: the largest (nearest) one wins
                d = fb / <double>v - doffs
                if d > 0:
                    fd = <float>d
                    old = out_d[r, c]
                    if isnan(old) or fd > old:
                        out_d[r, c] = fd
                continue
            old = out[r, c]
            if isnan(old) or (v < old if keep_min else v > old):
                out[r, c] = v
                if with_d:
                    d = fb / <double>v - doffs
                    out_d[r, c] = <float>d if d > 0 else NAN
    return bad
