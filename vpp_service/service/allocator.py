"""Keep freed frame-sized buffers in the process for reuse (glibc ``mallopt``).

Every frame allocates a few multi-MB arrays (decoded images, the painted pair,
disparity).  With glibc's defaults an array above the mmap threshold (128 KiB,
raised dynamically up to 32 MiB) gets fresh pages from the kernel, and each
4 KiB page costs a fault on first touch, and freed heap tops are returned to the
kernel (``M_TRIM_THRESHOLD``) only to be faulted in again next frame.
:func:`reuse_freed_memory` raises both thresholds so freed frames are reused:
the resident size then stays at the peak of a steady stream (a few frames in
flight) instead of going up and down every frame.

Only glibc has ``mallopt``; elsewhere this is a no-op that says so.

The price of keeping freed memory is that a one-off spike (a hostile message
as large as the caps allow, copied and rejected) would stay resident for good:
:func:`trim_freed_memory` (glibc ``malloc_trim``) hands free heap pages back to
the kernel, and the service calls it shortly after rejecting input.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import logging

log = logging.getLogger(__name__)

_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3


def _libc() -> ctypes.CDLL | None:
    name = ctypes.util.find_library("c")
    try:
        return ctypes.CDLL(name) if name else None
    except OSError:
        return None


def trim_freed_memory() -> bool:
    """Return the free pages of every heap to the kernel now (glibc ``malloc_trim(0)``).

    Returns
    -------
    bool
        True when this C library has ``malloc_trim`` (whether or not it found
        pages to release), False elsewhere.
    """
    libc = _libc()
    trim = getattr(libc, "malloc_trim", None) if libc is not None else None
    if trim is None:
        return False
    trim(0)
    return True


def reuse_freed_memory(mmap_threshold_mb: int = 512) -> bool:
    """Serve allocations below ``mmap_threshold_mb`` from the heap and never trim it.

    Parameters
    ----------
    mmap_threshold_mb : int
        Allocations at least this large still get their own mapping (and are
        returned to the kernel when freed); must be in [1, 1024].

    Returns
    -------
    bool
        True when applied (glibc), False when this C library has no ``mallopt``.

    Raises
    ------
    ValueError
        If ``mmap_threshold_mb`` is out of range.
    """
    if (
        isinstance(mmap_threshold_mb, bool)
        or not isinstance(mmap_threshold_mb, int)
        or not 1 <= mmap_threshold_mb <= 1024
    ):
        raise ValueError(f"mmap_threshold_mb must be an int in [1, 1024], got {mmap_threshold_mb!r}")
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name) if name else None
        mallopt = libc.mallopt if libc is not None else None
    except (OSError, AttributeError):
        mallopt = None
    if mallopt is None:
        log.info("allocator: no mallopt in this C library; freed frames are not kept for reuse")
        return False
    size = mmap_threshold_mb << 20
    ok = mallopt(_M_MMAP_THRESHOLD, size) == 1 and mallopt(_M_TRIM_THRESHOLD, 2 * size) == 1
    if not ok:
        log.warning("allocator: mallopt refused the thresholds; freed frames are not kept for reuse")
    return ok


__all__ = ["reuse_freed_memory", "trim_freed_memory"]
