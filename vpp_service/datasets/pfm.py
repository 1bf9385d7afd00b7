"""Portable Float Map (PFM) reading and writing.

PFM is the float image format of the Middlebury 2014 and ETH3D benchmarks. The
header is ``Pf`` (1 channel) or ``PF`` (3 channels), then ``width height``, then a
scale whose *sign* gives the byte order (negative = little-endian). Rows are
stored bottom-up, so they are flipped after reading and before writing.
"""

from __future__ import annotations

from pathlib import Path
from typing import BinaryIO

import numpy as np


def _token(fh: BinaryIO) -> bytes:
    """Read the next whitespace-separated header token (skipping ``#`` comments)."""
    out = b""
    while True:
        c = fh.read(1)
        if not c:
            break
        if c == b"#" and not out:
            fh.readline()
            continue
        if c.isspace():
            if out:
                break
            continue
        out += c
    return out


def read_pfm(path: str | Path) -> np.ndarray:
    """Read a PFM file.

    Parameters
    ----------
    path : str or Path
        File to read.

    Returns
    -------
    ndarray
        float32 array, H x W (``Pf``) or H x W x 3 (``PF``), top row first,
        native byte order. Values are returned as stored (``inf`` stays ``inf``).

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If the header is malformed or the file is truncated.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"path: PFM file not found: {path}")
    with open(path, "rb") as fh:
        magic = _token(fh)
        if magic not in (b"Pf", b"PF"):
            raise ValueError(f"path: {path} is not a PFM file (magic {magic!r})")
        channels = 1 if magic == b"Pf" else 3
        try:
            width, height = int(_token(fh)), int(_token(fh))
            scale = float(_token(fh))
        except ValueError:
            raise ValueError(f"path: {path} has a malformed PFM header") from None
        if width <= 0 or height <= 0 or scale == 0 or not np.isfinite(scale):
            raise ValueError(f"path: {path} has an invalid PFM header ({width}x{height}, scale {scale})")
        dtype = np.dtype("<f4") if scale < 0 else np.dtype(">f4")
        count = width * height * channels
        data = np.frombuffer(fh.read(count * 4), dtype=dtype)
    if data.size != count:
        raise ValueError(f"path: {path} is truncated ({data.size} of {count} values)")
    shape = (height, width) if channels == 1 else (height, width, 3)
    return np.ascontiguousarray(np.flipud(data.reshape(shape)).astype(np.float32))


def write_pfm(path: str | Path, array: np.ndarray) -> None:
    """Write a float array as a little-endian PFM file.

    Parameters
    ----------
    path : str or Path
        Destination (parent folder must exist).
    array : ndarray
        H x W or H x W x 3 real array; written as float32, top row first in
        ``array`` (stored bottom-up as the format requires).

    Raises
    ------
    TypeError
        If ``array`` is not a real numeric ndarray.
    ValueError
        If ``array`` has the wrong number of dimensions/channels or is empty.
    """
    real = isinstance(array, np.ndarray) and (
        np.issubdtype(array.dtype, np.floating) or np.issubdtype(array.dtype, np.integer)
    )
    if not real:
        raise TypeError(f"array: must be a real numeric ndarray, got {type(array).__name__}")
    if array.ndim == 3 and array.shape[2] == 1:
        array = array[..., 0]
    if array.ndim not in (2, 3) or (array.ndim == 3 and array.shape[2] != 3):
        raise ValueError(f"array: must be H x W or H x W x 3, got shape {array.shape}")
    if array.size == 0:
        raise ValueError("array: must not be empty")
    h, w = array.shape[:2]
    magic = b"Pf" if array.ndim == 2 else b"PF"
    data = np.flipud(array).astype("<f4")
    with open(path, "wb") as fh:
        fh.write(magic + b"\n" + f"{w} {h}\n".encode() + b"-1\n")
        fh.write(np.ascontiguousarray(data).tobytes())


__all__ = ["read_pfm", "write_pfm"]
