"""Per-pixel primitives shared by the VPP kernels (``_kernel.pyx``, ``_sweep.pyx``).

All arithmetic is the fixed-point rule documented in :mod:`vpp_service.vpp.project`.
"""
from libc.stdint cimport uint8_t, int64_t, uint64_t
from libc.math cimport floor


cdef inline uint64_t _hash(uint64_t seedmix, uint64_t x, uint64_t y) noexcept nogil:
    """splitmix64 finaliser of ``seedmix + ((y << 32) | x) * KEY_MUL`` (see ``rng.py``)."""
    cdef uint64_t z = seedmix + ((y << 32) | x) * <uint64_t>0x9E3779B97F4A7C15ULL
    z = (z ^ (z >> 30)) * <uint64_t>0xBF58476D1CE4E5B9ULL
    z = (z ^ (z >> 27)) * <uint64_t>0x94D049BB133111EBULL
    return z ^ (z >> 31)


cdef inline uint64_t _seedmix(uint64_t seed) noexcept nogil:
    return seed * <uint64_t>0xD1B54A32D192ED03ULL


cdef enum:
    PAT_ROW_STEP = 23679    # rng.ROW_STEP
    PAT_MASK = 65535        # rng.TABLE_SIZE - 1


cdef inline int64_t _pidx(int64_t x, int64_t y) noexcept nogil:
    """Pattern-table index of pixel (x, y): ``(x + y * ROW_STEP) mod TABLE_SIZE`` (see ``rng.py``).

    The table given to the kernels is padded past ``TABLE_SIZE`` entries with a
    copy of its start, so ``_pidx(x0, y) + k`` reads pixel ``x0 + k`` directly."""
    return (x + y * PAT_ROW_STEP) & PAT_MASK


cdef inline uint64_t _w16(double w) noexcept nogil:
    """Weight in [0, 1] -> fixed point /65536, rounded half up (truncation is floor for w >= 0)."""
    return <uint64_t><int64_t>(w * 65536.0 + 0.5)   # via int64: one cvttsd2si


cdef inline int _ifloor(double v) noexcept nogil:
    """floor(v) as an int for |v| < 2**31 (no libm call)."""
    cdef int i = <int>v
    return i - 1 if <double>i > v else i


cdef inline uint8_t _blend16(uint8_t a, uint8_t b, uint64_t w) noexcept nogil:
    """round((1 - w) a + w b) with w in 1/65536 (half up)."""
    return <uint8_t>(((<uint64_t>a) * (65536 - w) + (<uint64_t>b) * w + 32768) >> 16)


cdef inline void _fgd_pixel(uint8_t* lp, const uint8_t* rp, int C, bint interp,
                            uint64_t wb, uint64_t wa) noexcept nogil:
    """FGD: blend the right view at x' (linearly interpolated between ``rp`` and
    the next pixel with weight ``wb`` when ``interp``) into the left pixel ``lp``
    with weight ``wa`` (both 1/65536 fixed point, round half up)."""
    cdef int c
    cdef uint64_t v16, src
    for c in range(C):
        if interp:
            v16 = <uint64_t>rp[c] * (65536 - wb) + <uint64_t>rp[C + c] * wb
        else:
            v16 = <uint64_t>rp[c] * 65536
        src = lp[c]
        lp[c] = <uint8_t>((src * (65536 - wa) * 65536 + v16 * wa + 2147483648ULL) >> 32)
