"""Damaged copies of rosbag2 bags: cut short, or 4 KiB of garbage written in; MCAP chunk CRCs filled in.

rosbags writes every MCAP chunk with CRC 0 ("not computed"); ros2 bag record (the mcap
C++ writer) writes the CRC-32 of each chunk's uncompressed records. :func:`seal_chunk_crcs`
turns a rosbags bag into the latter. The MCAP walk here follows the format's
specification (magic; records of opcode u8, length u64, content; a chunk holds start
time u64, end time u64, uncompressed size u64, CRC u32, compression string, records
length u64, records), written apart from vpp_service's reader.
"""

from __future__ import annotations

import struct
from binascii import crc32
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from helpers.ros2_robot import StereoRig, write_bag
from vpp_service.transport.ros2.mcap_reader import zstd_module

zstd = zstd_module()

MAGIC = b"\x89MCAP0\r\n"
#: 20 stamps 0.1 s apart; write_bag logs message i (of five) of a stamp at stamp + i us.
STAMPS = [1_000_000_000 + i * 100_000_000 for i in range(20)]


def textured_rig() -> StereoRig:
    """128 x 160 random RGB pairs: 20 stamps make about 2.5 MB (three MCAP chunks, about 600 sqlite pages)."""
    rng = np.random.default_rng(1)
    left = rng.integers(0, 256, (128, 160, 3), dtype=np.uint8)
    right = rng.integers(0, 256, (128, 160, 3), dtype=np.uint8)
    return StereoRig(left, right, 100.0, 0.1, 3.5, 5.5, 2.5, np.array([[0, 0, 2.0], [0, 0, -1.0]], np.float32))


def write_test_bag(folder: Path, storage: str, zstd: bool = False, crc: bool = True) -> Path:
    """The storage file of a new bag of :func:`textured_rig` at :data:`STAMPS` (MCAP: chunk CRCs unless not ``crc``)."""
    write_bag(str(folder), storage, textured_rig(), STAMPS, zstd=zstd)
    f = bag_file(folder)
    if storage == "mcap" and crc:
        seal_chunk_crcs(f)
    return f


@dataclass(frozen=True)
class Chunk:
    """One MCAP chunk: its record's byte range in the file and the log times of its messages."""

    start: int
    end: int
    log_times: tuple[int, ...]


def bag_file(folder: Path) -> Path:
    """The one storage file (.mcap or .db3) of a bag folder."""
    (f,) = [p for p in folder.iterdir() if p.suffix in (".mcap", ".db3")]
    return f


def _chunk_fields(data: bytes, start: int) -> tuple[int, bytes]:
    """(offset of the CRC field, uncompressed records) of the chunk record at ``start``."""
    pos = start + 9 + 24
    crc_at = pos
    pos += 4
    (n,) = struct.unpack_from("<I", data, pos)
    compression = data[pos + 4 : pos + 4 + n].decode()
    pos += 4 + n
    (length,) = struct.unpack_from("<Q", data, pos)
    records = data[pos + 8 : pos + 8 + length]
    return crc_at, (zstd.decompress(records) if compression == "zstd" else records)


def mcap_chunks(path: Path) -> list[Chunk]:
    """Every chunk of an intact MCAP file, in file order."""
    data = path.read_bytes()
    assert data[:8] == MAGIC
    pos, out = 8, []
    while pos < len(data) - 8:
        op, length = data[pos], struct.unpack_from("<Q", data, pos + 1)[0]
        if op == 0x06:
            _, raw = _chunk_fields(data, pos)
            times, q = [], 0
            while q < len(raw):
                rop, rlen = raw[q], struct.unpack_from("<Q", raw, q + 1)[0]
                if rop == 0x05:
                    times.append(struct.unpack_from("<Q", raw, q + 9 + 6)[0])  # channel u16, sequence u32
                q += 9 + rlen
            out.append(Chunk(pos, pos + 9 + length, tuple(times)))
        if op == 0x02:  # footer
            break
        pos += 9 + length
    return out


def seal_chunk_crcs(path: Path) -> None:
    """Write each chunk's CRC-32 (of its uncompressed records) into its CRC field, as ros2 bag record does."""
    data = bytearray(path.read_bytes())
    for chunk in mcap_chunks(path):
        crc_at, raw = _chunk_fields(bytes(data), chunk.start)
        struct.pack_into("<I", data, crc_at, crc32(raw))
    path.write_bytes(bytes(data))


def cut(src: Path, dst: Path, fraction: float) -> Path:
    """``dst``: the first ``fraction`` of ``src``'s bytes (a copy interrupted, a recorder killed)."""
    data = src.read_bytes()
    dst.write_bytes(data[: int(len(data) * fraction)])
    return dst


def garble(src: Path, dst: Path, at: int | None = None, n: int = 4096, seed: int = 0) -> Path:
    """``dst``: ``src`` with ``n`` random bytes written over it at byte ``at`` (default: the middle)."""
    data = bytearray(src.read_bytes())
    at = len(data) // 2 if at is None else at
    data[at : at + n] = np.random.default_rng(seed).bytes(n)
    dst.write_bytes(bytes(data))
    return dst
