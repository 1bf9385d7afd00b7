"""Which build of the sweep kernel runs.

The kernel (:mod:`vpp_service.vpp._sweep`) is compiled twice: a portable build
(SSE2 on x86-64, plain C elsewhere) and, on x86-64, ``_sweep_avx2`` compiled
for x86-64-v3 (AVX2, FMA, BMI2, ...).  Both give the same bytes.  The AVX2
build is imported only after the portable one has checked that the CPU
supports it (importing it on an older CPU would crash); ``VPP_NO_AVX2=1`` in
the environment keeps the portable build.  This is the only place that
chooses: nothing else in the package tests the CPU.

Attributes
----------
sweep : module
    The build in use (``project`` and ``detect_occlusions`` call it).
AVX2 : bool
    True when ``sweep`` is the AVX2 build.
"""

from __future__ import annotations

import os
from types import ModuleType

from vpp_service.vpp import _sweep as portable


def avx2_build() -> ModuleType | None:
    """The AVX2 build when it exists and this CPU can run it, else None."""
    if not portable.cpu_supports_avx2():
        return None
    try:
        from vpp_service.vpp import _sweep_avx2
    except ImportError:  # not built (non-x86 platform or a compiler without -mavx2)
        return None
    return _sweep_avx2


def _choose() -> ModuleType:
    if os.environ.get("VPP_NO_AVX2", "0") == "1":
        return portable
    return avx2_build() or portable


sweep: ModuleType = _choose()
AVX2: bool = bool(sweep.AVX2)


def release_scratch() -> int:
    """Free the sweep kernel's per-thread work buffers kept between calls.

    Each thread of a call uses a few MB of buffers (for the widest image seen
    so far); they are pooled and reused by later calls instead of being
    mapped afresh.  Call this to hand that memory back, e.g. after processing
    an unusually large image; the next call allocates again.

    Returns
    -------
    int
        Number of buffer sets freed (both builds).
    """
    n = portable.release_scratch()
    if sweep is not portable:
        n += sweep.release_scratch()
    return n


__all__ = ["AVX2", "avx2_build", "portable", "release_scratch", "sweep"]
