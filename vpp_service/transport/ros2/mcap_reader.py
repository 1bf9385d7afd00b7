"""MCAP files (rosbag2's ``.mcap``) read record by record, so damage costs only the messages it touches.

rosbags' reader starts from the summary section at the end of the file (gone when a
file is cut short) and raises at the first damaged chunk. This reader walks the
records from the start instead (magic, then ``opcode u8, length u64,
content``), and reports every damaged place through ``on_damage``
(:mod:`~vpp_service.transport.ros2.bag_damage`):

- a chunk is decompressed (none, ``zstd`` or ``lz4``, what ros2 bag record and rosbags
  write) to at most its declared size, and checked against its CRC-32 when it has one
  (ros2 bag record writes them; rosbags, so also this project's rosbag2 sink, writes 0,
  "not computed"): a chunk that fails is skipped whole (``bag.crc``,
  ``bag.corrupt_chunk``). Garbage inside the message bytes of a chunk without a CRC
  cannot be seen; broken framing in it still is;
- a file cut short plays the complete messages of its last, partial chunk, then stops
  (``bag.truncated``; also when only the summary is cut, with every message read);
- broken framing outside a chunk (``bag.corrupt_record``) skips to the next chunk
  named by the file's chunk index when the summary is intact, else ends the file; a
  footer whose summary offset follows no Data End record is not believed.

Every record's length is checked against the bytes left in the file (and chunks
against :data:`MAX_RECORD_BYTES`) before it is read or decompressed. Messages come out
in file order, each chunk's sorted by log time: log-time order for any bag recorded
in order (ros2 bag record, rosbags and :class:`~vpp_service.transport.ros2.bag.BagWriter`
write their chunks one after another).
"""

from __future__ import annotations

import os
import sys
from binascii import crc32
from bisect import bisect_right
from collections.abc import Collection, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import BinaryIO

from vpp_service.transport.ros2.bag_damage import BagDamage, OnDamage, ignore_damage
from vpp_service.transport.ros2.bag_message import BagMessage

MAGIC = b"\x89MCAP0\r\n"
#: The largest chunk (compressed or not) read; a record claiming more is damage. ros2 bag
#: record's chunks are 768 KiB unless one message is larger (a 4K RGB image is 25 MB).
MAX_RECORD_BYTES = 256 << 20

OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK, OP_DATA_END = 0x02, 0x03, 0x04, 0x05, 0x06, 0x0F
OP_CHUNK_INDEX = 0x08
#: Footer record (opcode, length 20, summary start, summary offset start, CRC) and the closing magic.
_FOOTER_LEN = 9 + 20 + len(MAGIC)
_RECORD_HEAD = 9
#: A Data End record (its content: the data section's CRC, u32), which the summary section follows.
_DATA_END_LEN = _RECORD_HEAD + 4
#: A chunk's fixed fields: start and end time, uncompressed size, CRC.
_CHUNK_HEAD = 8 + 8 + 8 + 4


class _Bad(Exception):
    """A record whose content does not hold (the message names what)."""


class _Fields:
    """Little-endian fields read from a record's content, none past its end."""

    def __init__(self, buf: bytes | memoryview) -> None:
        self.buf = memoryview(buf)
        self.pos = 0

    def take(self, n: int) -> memoryview:
        if n > len(self.buf) - self.pos:
            raise _Bad(f"a field of {n} bytes runs past the end of its record")
        v = self.buf[self.pos : self.pos + n]
        self.pos += n
        return v

    def uint(self, n: int) -> int:
        return int.from_bytes(self.take(n), "little")

    def string(self) -> str:
        try:
            return bytes(self.take(self.uint(4))).decode()
        except UnicodeDecodeError:
            raise _Bad("a string that is not UTF-8") from None

    def rest(self) -> memoryview:
        return self.take(len(self.buf) - self.pos)


def zstd_module() -> ModuleType:
    """The standard library's ``compression.zstd`` (Python 3.14 on), else ``backports.zstd`` (a dependency)."""
    if sys.version_info >= (3, 14):
        from compression import zstd
    else:
        from backports import zstd
    return zstd


def _records(buf: bytes | memoryview, partial: bool = False) -> Iterator[tuple[int, memoryview]]:
    """(opcode, content) of the records in ``buf``; a cut last record ends it when ``partial``."""
    view, pos = memoryview(buf), 0
    while pos < len(view):
        if len(view) - pos < _RECORD_HEAD:
            if partial:
                return
            raise _Bad(f"a record header cut at byte {pos}")
        op, length = view[pos], int.from_bytes(view[pos + 1 : pos + _RECORD_HEAD], "little")
        if length > len(view) - pos - _RECORD_HEAD:
            if partial:
                return
            raise _Bad(f"record {op:#04x} at byte {pos} claims {length} bytes, {len(view) - pos - 9} are left")
        yield op, view[pos + _RECORD_HEAD : pos + _RECORD_HEAD + length]
        pos += _RECORD_HEAD + length


@dataclass
class _Summary:
    """What the footer and the summary section say: where data ends, where chunks start, definitions."""

    data_end: int
    chunk_starts: list[int] = field(default_factory=list)
    chunk_set: frozenset[int] = frozenset()
    schemas: dict[int, str] = field(default_factory=dict)
    channels: dict[int, tuple[str, int]] = field(default_factory=dict)
    #: Why the footer is not believed ("": it is); the data section then ends at the first Data End record.
    untrusted: str = ""


def _definition(op: int, content: memoryview, schemas: dict[int, str], channels: dict[int, tuple[str, int]]) -> None:
    """Record a schema (id -> type name) or channel (id -> topic, schema id)."""
    f = _Fields(content)
    if op == OP_SCHEMA:
        sid = f.uint(2)
        schemas[sid] = f.string()
    elif op == OP_CHANNEL:
        cid, sid = f.uint(2), f.uint(2)
        channels[cid] = (f.string(), sid)


def _read_summary(f: BinaryIO, size: int) -> _Summary | None:
    """The summary of a file with an intact footer (None without one: the file was cut or its end damaged)."""
    if size < len(MAGIC) + _FOOTER_LEN:
        return None
    footer_start = size - _FOOTER_LEN
    f.seek(footer_start)
    tail = f.read(_FOOTER_LEN)
    if tail[-len(MAGIC) :] != MAGIC or tail[0] != OP_FOOTER or int.from_bytes(tail[1:9], "little") != 20:
        return None
    start = int.from_bytes(tail[9:17], "little")
    if start == 0 or not len(MAGIC) + _DATA_END_LEN <= start <= footer_start or footer_start - start > MAX_RECORD_BYTES:
        return _Summary(footer_start)  # no (usable) summary: the data section runs to the footer
    f.seek(start - _DATA_END_LEN)
    if f.read(_RECORD_HEAD) != bytes([OP_DATA_END]) + (4).to_bytes(8, "little"):  # trust none of it
        return _Summary(footer_start, untrusted=f"the footer's summary offset {start} follows no Data End record")
    summary = _Summary(start)
    f.seek(start)
    try:
        for op, content in _records(f.read(footer_start - start)):
            if op in (OP_SCHEMA, OP_CHANNEL):
                _definition(op, content, summary.schemas, summary.channels)
            elif op == OP_CHUNK_INDEX:
                summary.chunk_starts.append(_Fields(content[16:24]).uint(8))
    except _Bad:
        return _Summary(start)  # the index is damaged: walk without it
    summary.chunk_starts.sort()
    summary.chunk_set = frozenset(summary.chunk_starts)
    return summary


def _decompress(compression: str, data: memoryview, size: int, partial: bool) -> bytes:
    """A chunk's records, at most ``size`` bytes (``partial``: as much as a cut chunk gives)."""
    if compression == "":
        return bytes(data[:size])
    try:
        if compression == "zstd":
            zd = zstd_module().ZstdDecompressor()
            out = zd.decompress(data, max_length=size)
            if not partial and not zd.eof:
                raise _Bad(f"its zstd data does not end within {size} bytes")
            return out
        if compression == "lz4":
            from lz4.frame import LZ4FrameDecompressor

            ld = LZ4FrameDecompressor()
            out = ld.decompress(data, max_length=size)
            if not partial and not ld.eof:
                raise _Bad(f"its lz4 data does not end within {size} bytes")
            return bytes(out)
    except _Bad:
        raise
    except Exception as exc:  # noqa: BLE001 - zstd.ZstdError, lz4's RuntimeError: the data is damaged
        raise _Bad(f"its {compression} data does not decompress ({exc})") from None
    raise _Bad(f"unknown compression {compression!r}")


class McapWalk:
    """The messages of one ``.mcap`` file, read from the start (see the module docstring).

    Parameters
    ----------
    path : str or Path
        The ``.mcap`` file.
    topics : collection of str, optional
        Topics to yield (None = all).
    on_damage : callable
        Receives each damaged place (:class:`~vpp_service.transport.ros2.bag_damage.BagDamage`).

    Attributes
    ----------
    channels : dict
        Channel id -> (topic, schema id), as found so far (all of them after a full pass).
    schemas : dict
        Schema id -> message type.
    read : int
        Messages yielded so far.
    """

    def __init__(
        self, path: str | Path, topics: Collection[str] | None = None, on_damage: OnDamage = ignore_damage
    ) -> None:
        self.path = Path(path)
        self.topics = topics
        self.on_damage = on_damage
        self.schemas: dict[int, str] = {}
        self.channels: dict[int, tuple[str, int]] = {}
        self.read = 0
        self._chunks = 0

    def _damage(self, cause: str, where: str) -> None:
        self.on_damage(BagDamage(cause, f"{self.path}: {where} (after {self.read} messages read)"))

    def summary_topics(self) -> dict[str, str] | None:
        """Topic -> type from the summary section, without a pass (None when the file has none)."""
        with self.path.open("rb") as f:
            size = os.fstat(f.fileno()).st_size
            summary = _read_summary(f, size)
        if summary is None or not summary.channels:
            return None
        return {topic: summary.schemas.get(sid, "") for topic, sid in summary.channels.values()}

    def __iter__(self) -> Iterator[BagMessage]:
        with self.path.open("rb") as f:
            size = os.fstat(f.fileno()).st_size
            if f.read(len(MAGIC)) != MAGIC:
                raise ValueError(f"rosbag: {self.path}: not an MCAP file (its first bytes are not the MCAP magic)")
            summary = _read_summary(f, size)
            if summary is not None:
                self.schemas.update(summary.schemas)
                self.channels.update(summary.channels)
                if summary.untrusted:
                    self._damage("bag.corrupt_record", f"{summary.untrusted}: read without the file's index")
            yield from self._walk(f, size, summary)

    def _walk(self, f: BinaryIO, size: int, summary: _Summary | None) -> Iterator[BagMessage]:
        end = size if summary is None else summary.data_end
        pos = len(MAGIC)
        while pos < end:
            f.seek(pos)
            head = f.read(_RECORD_HEAD)
            if len(head) < _RECORD_HEAD:
                self._damage("bag.truncated", f"the file ends at byte {size}, inside the record at byte {pos}")
                return
            op, length = head[0], int.from_bytes(head[1:], "little")
            stop = pos + _RECORD_HEAD + length
            if op in (OP_DATA_END, OP_FOOTER) and (
                summary is None or summary.untrusted or (op == OP_DATA_END and stop == end)
            ):
                break  # the end of the data section (a footer here: the file's end was cut, reported below)
            indexed = summary is None or not summary.chunk_starts or pos in summary.chunk_set
            if op in (0, OP_DATA_END, OP_FOOTER) or 0x10 <= op < 0x80 or (op == OP_CHUNK and not indexed):
                why = f"opcode {op:#04x}" + (" not in the chunk index" if op == OP_CHUNK else " out of place")
                pos = self._resync(summary, pos, end, why)
                continue
            if stop > end:
                if summary is None:  # no footer: the file was cut inside this record
                    where = f"the record at byte {pos}"
                    if op == OP_CHUNK:
                        before = self.read
                        yield from self._partial_chunk(f, pos, size)
                        where = f"chunk {self._chunks} (at byte {pos}; {self.read - before} of its messages read)"
                    self._damage("bag.truncated", f"the file ends at byte {size}, inside {where}")
                    return
                pos = self._resync(summary, pos, end, f"opcode {op:#04x} claims {length} bytes past the data end")
                continue
            if op == OP_CHUNK:
                self._chunks += 1
                if length > MAX_RECORD_BYTES:
                    self._damage("bag.corrupt_chunk", f"chunk {self._chunks} at byte {pos}: {length} bytes is too big")
                else:
                    yield from self._chunk(f.read(length), pos)
            elif op in (OP_SCHEMA, OP_CHANNEL, OP_MESSAGE) and length > MAX_RECORD_BYTES:
                self._damage("bag.corrupt_record", f"record {op:#04x} at byte {pos} skipped: {length} bytes is too big")
            elif op in (OP_SCHEMA, OP_CHANNEL, OP_MESSAGE):
                try:
                    msgs = list(self._apply([(op, memoryview(f.read(length)))]))
                except _Bad as exc:
                    pos = self._resync(summary, pos, end, str(exc))
                    continue
                yield from self._sorted(msgs)
            pos = stop
        if summary is None:
            self._damage("bag.truncated", f"the file ends at byte {size} without the MCAP footer")

    def _resync(self, summary: _Summary | None, pos: int, end: int, why: str) -> int:
        """Where reading goes on after broken framing at ``pos``: the next indexed chunk, or the end."""
        starts = summary.chunk_starts if summary is not None else []
        i = bisect_right(starts, pos)
        nxt = starts[i] if i < len(starts) else None
        if nxt is None:
            self._damage("bag.corrupt_record", f"broken record at byte {pos} ({why}): bytes {pos}-{end} unreadable")
            return end
        self._damage("bag.corrupt_record", f"broken record at byte {pos} ({why}): skipped to the chunk at byte {nxt}")
        return nxt

    def _chunk_records(self, content: bytes | memoryview, partial: bool) -> list[tuple[int, memoryview]]:
        """A chunk's inner records, checked against its CRC unless ``partial`` (a cut chunk's complete ones)."""
        f = _Fields(content)
        f.take(16)  # message start and end time
        size, crc = f.uint(8), f.uint(4)
        compression = f.string()
        length = f.uint(8)
        data = f.rest()
        if size > MAX_RECORD_BYTES:
            raise _Bad(f"its uncompressed size {size} is too big")
        if not partial and length != len(data):
            raise _Bad(f"its data claims {length} bytes, the record holds {len(data)}")
        raw = _decompress(compression, data[:length], size, partial)
        if not partial:
            if len(raw) != size:
                raise _Bad(f"it decompresses to {len(raw)} bytes, not {size}")
            if crc and crc32(raw) != crc:
                raise _CrcMismatch(f"CRC-32 {crc32(raw):#010x}, recorded {crc:#010x}")
        return list(_records(raw, partial))

    def _chunk(self, content: bytes, pos: int) -> Iterator[BagMessage]:
        try:
            records = self._chunk_records(content, partial=False)
            msgs = list(self._apply(records))
        except _CrcMismatch as exc:
            self._damage("bag.crc", f"chunk {self._chunks} at byte {pos} skipped: {exc}")
            return
        except _Bad as exc:
            self._damage("bag.corrupt_chunk", f"chunk {self._chunks} at byte {pos} skipped: {exc}")
            return
        yield from self._sorted(msgs)

    def _partial_chunk(self, f: BinaryIO, pos: int, size: int) -> Iterator[BagMessage]:
        """The complete messages of the chunk the file was cut in."""
        self._chunks += 1
        f.seek(pos + _RECORD_HEAD)
        try:
            records = self._chunk_records(f.read(min(size - pos - _RECORD_HEAD, MAX_RECORD_BYTES)), partial=True)
            msgs = list(self._apply(records))
        except _Bad:
            return  # the chunk's own header is cut or damaged: nothing in it is readable
        yield from self._sorted(msgs)

    def _sorted(self, msgs: list[BagMessage]) -> Iterator[BagMessage]:
        for m in sorted(msgs, key=lambda m: m.log_time_ns):
            self.read += 1
            yield m

    def _apply(self, records: list[tuple[int, memoryview]]) -> Iterator[BagMessage]:
        """Take in definitions; yield the messages on the chosen topics (unsorted, not yet counted)."""
        unknown = 0
        for op, content in records:
            if op in (OP_SCHEMA, OP_CHANNEL):
                _definition(op, content, self.schemas, self.channels)
            elif op == OP_MESSAGE:
                f = _Fields(content)
                cid = f.uint(2)
                f.take(4)  # sequence
                log_time = f.uint(8)
                f.take(8)  # publish time
                channel = self.channels.get(cid)
                if channel is None:
                    unknown += 1
                elif self.topics is None or channel[0] in self.topics:
                    yield BagMessage(channel[0], self.schemas.get(channel[1], ""), log_time, bytes(f.rest()))
        if unknown:
            self._damage("bag.unknown_channel", f"{unknown} messages on channels no readable record defines")


class _CrcMismatch(_Bad):
    """A chunk whose bytes do not match its CRC-32."""


__all__ = ["MAX_RECORD_BYTES", "McapWalk", "zstd_module"]
