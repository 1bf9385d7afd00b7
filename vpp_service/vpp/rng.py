"""The seeded random pattern: a per-seed byte table indexed by pixel.

A pattern value must not depend on painting order or on the thread that paints
it, so it is a pure function of ``(seed, x, y, c)``:

* the seed's *table* is ``TABLE_SIZE * C`` bytes: byte ``i`` is byte ``i % 8``
  (little-endian) of :func:`pattern_hash` ``(seed, i // 8 + 1, 0)``, the
  splitmix64 finaliser of ``seed * 0xD1B54A32D192ED03 + (i // 8 + 1) *
  0x9E3779B97F4A7C15`` (all modulo 2**64; the ``+ 1`` keeps the all-zero word,
  splitmix64's fixed point, out of seed 0's table);
* pixel ``(x, y)`` has the table index ``(x + y * ROW_STEP) mod TABLE_SIZE``
  (:func:`pattern_index`) and channel ``c`` of its value is table byte
  ``C * index + c``.

Consecutive pixels of a row are consecutive table entries, so a patch row's
pattern is one contiguous span of the table: the kernel reads it in place
instead of hashing every pixel.  The values are independent uniform bytes except
where two pixels share an index, i.e. ``dx + dy * ROW_STEP = 0 (mod 2**16)``:
never within a row of up to 65536 pixels, never for ``1 <= |dy| <= 16`` and
``|dx| < 1000``, and nowhere closer than 274 pixels (``ROW_STEP`` maximises
that distance, the shortest vector of the lattice, whose optimum is about 275).
A stereo matcher compares windows along rows, so it never sees a repeat.

The kernel reads the table built by ``backend.sweep.fill_pattern_table``
(the same bytes, tested); this NumPy version is
the reference used by the tests.
"""

from __future__ import annotations

import functools

import numpy as np

SEED_MUL = 0xD1B54A32D192ED03
KEY_MUL = 0x9E3779B97F4A7C15
M1 = 0xBF58476D1CE4E5B9
M2 = 0x94D049BB133111EB
MASK64 = (1 << 64) - 1
#: table entries (pixels) per seed; the pattern of a row repeats after this many columns
TABLE_BITS = 16
TABLE_SIZE = 1 << TABLE_BITS
#: index step from one row to the next (odd; see the module docstring)
ROW_STEP = 23679


def check_seed(seed: object) -> int:
    """Validate a seed: an int in ``[0, 2**64)``; returns it as a Python int."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
        raise TypeError(f"seed must be an int, got {type(seed).__name__}")
    seed = int(seed)
    if not 0 <= seed <= MASK64:
        raise ValueError(f"seed must be in [0, 2**64), got {seed}")
    return seed


def _check_channels(channels: object) -> int:
    if isinstance(channels, bool) or not isinstance(channels, (int, np.integer)) or channels < 1:
        raise ValueError(f"channels must be an int >= 1, got {channels!r}")
    return int(channels)


def pattern_hash(seed: int, x: np.ndarray | int, y: np.ndarray | int) -> np.ndarray:
    """64-bit splitmix64 hash of ``(x, y)`` for ``seed`` (vectorised).

    Parameters
    ----------
    seed : int
        Seed in ``[0, 2**64)``.
    x, y : array_like of int
        Non-negative integers (< 2**32), broadcast together.

    Returns
    -------
    numpy.ndarray of uint64
    """
    seed = check_seed(seed)
    x = np.asarray(x, dtype=np.uint64)
    y = np.asarray(y, dtype=np.uint64)
    smix = np.uint64((seed * SEED_MUL) & MASK64)
    with np.errstate(over="ignore"):
        z = smix + ((y << np.uint64(32)) | x) * np.uint64(KEY_MUL)
        z = (z ^ (z >> np.uint64(30))) * np.uint64(M1)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(M2)
        return z ^ (z >> np.uint64(31))


def pattern_table(seed: int, channels: int) -> np.ndarray:
    """The seed's pattern table: ``TABLE_SIZE * channels`` uint8 values (read-only, cached).

    Parameters
    ----------
    seed : int
        Seed in ``[0, 2**64)``.
    channels : int
        Image channels (>= 1).
    """
    return _table(check_seed(seed), _check_channels(channels))


@functools.lru_cache(maxsize=8)
def _table(seed: int, channels: int) -> np.ndarray:
    n = TABLE_SIZE * channels
    words = pattern_hash(seed, np.arange(1, (n + 7) // 8 + 1, dtype=np.uint64), 0)
    table = words.astype("<u8").view(np.uint8)[:n].copy()
    table.flags.writeable = False
    return table


def pattern_index(x: np.ndarray | int, y: np.ndarray | int) -> np.ndarray:
    """Table index ``(x + y * ROW_STEP) mod TABLE_SIZE`` of pixel ``(x, y)`` (vectorised)."""
    x = np.asarray(x, dtype=np.int64)
    y = np.asarray(y, dtype=np.int64)
    return (x + y * ROW_STEP) & (TABLE_SIZE - 1)


def pattern_bytes(seed: int, x: np.ndarray | int, y: np.ndarray | int, channels: int) -> np.ndarray:
    """Random pattern values, shape ``broadcast(x, y).shape + (channels,)``, uint8."""
    table = pattern_table(seed, channels).reshape(TABLE_SIZE, channels)
    return table[pattern_index(x, y)]


def kernel_table(seed: int, channels: int, hmax: int) -> np.ndarray:
    """The pattern table as the Cython kernels read it (read-only, cached).

    The same bytes as :func:`pattern_table`, built by the compiled kernel
    followed by a copy of its first bytes so that a
    patch row of ``2 hmax + 1`` pixels starting at any entry is one contiguous
    span (``backend.sweep.table_padding``).

    Parameters
    ----------
    seed : int
        Seed in ``[0, 2**64)``.
    channels : int
        Image channels (>= 1).
    hmax : int
        Largest patch half-size (>= 0).
    """
    channels = _check_channels(channels)
    if isinstance(hmax, bool) or not isinstance(hmax, (int, np.integer)) or hmax < 0:
        raise ValueError(f"hmax must be an int >= 0, got {hmax!r}")
    return _kernel_table(check_seed(seed), channels, int(hmax))


@functools.lru_cache(maxsize=4)
def _kernel_table(seed: int, channels: int, hmax: int) -> np.ndarray:
    from vpp_service.vpp import backend

    sweep = backend.sweep
    table = np.empty(TABLE_SIZE * channels + sweep.table_padding(channels, hmax), np.uint8)
    sweep.fill_pattern_table(seed, table, channels)
    table.flags.writeable = False
    return table
