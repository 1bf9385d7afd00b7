"""The counter-based random generator behind the random pattern.

A pattern value must not depend on painting order or on the thread that paints
it, so it is a pure function of ``(seed, x, y)``: the splitmix64 finaliser of
``seed * 0xD1B54A32D192ED03 + ((y << 32) | x) * 0x9E3779B97F4A7C15`` (all modulo
2**64).  Byte ``c`` of the 64-bit result (``(h >> 8c) & 255``) is the value of
channel ``c``.  The Cython kernel implements exactly the same function; this
vectorised NumPy version is the reference used by the tests.
"""
from __future__ import annotations

import numpy as np

SEED_MUL = 0xD1B54A32D192ED03
KEY_MUL = 0x9E3779B97F4A7C15
M1 = 0xBF58476D1CE4E5B9
M2 = 0x94D049BB133111EB
MASK64 = (1 << 64) - 1


def check_seed(seed: object) -> int:
    """Validate a seed: an int in ``[0, 2**64)``; returns it as a Python int."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
        raise TypeError(f"seed must be an int, got {type(seed).__name__}")
    seed = int(seed)
    if not 0 <= seed <= MASK64:
        raise ValueError(f"seed must be in [0, 2**64), got {seed}")
    return seed


def pattern_hash(seed: int, x: np.ndarray | int, y: np.ndarray | int) -> np.ndarray:
    """64-bit hash of pixel ``(x, y)`` for ``seed`` (vectorised).

    Parameters
    ----------
    seed : int
        Seed in ``[0, 2**64)``.
    x, y : array_like of int
        Non-negative pixel coordinates (< 2**32), broadcast together.

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
        z = z ^ (z >> np.uint64(31))
    return z


def pattern_bytes(seed: int, x: np.ndarray | int, y: np.ndarray | int, channels: int) -> np.ndarray:
    """Random pattern values, shape ``broadcast(x, y).shape + (channels,)``, uint8."""
    z = pattern_hash(seed, x, y)
    shifts = (np.arange(channels, dtype=np.uint64) * np.uint64(8))
    return ((z[..., None] >> shifts) & np.uint64(255)).astype(np.uint8)
