"""Zero-copy msgpack decoding: ``bin`` fields come back as views of the payload.

``msgpack.unpackb`` copies every ``bin`` field into a new ``bytes`` object; for
a stereo frame that is a second copy of both images, on top of the
unavoidable copy out of the Zenoh buffer. :func:`loads` decodes the same format but returns each ``bin`` as a
read-only ``memoryview`` slice of the payload (``numpy.frombuffer`` wraps it
without copying; the view keeps the payload alive).

Everything else matches ``msgpack.unpackb(raw=False, strict_map_key=True,
use_list=True)``: nil, booleans, integers, float32/64, UTF-8 strings, arrays
(lists) and maps (dicts with str or bytes keys). Extension types are refused,
as are the never-used byte 0xc1, truncated input, trailing bytes, containers
or strings longer than the given limits and nesting deeper than ``max_depth``.
Every error is a :class:`MsgViewError` (a ``ValueError``) saying what and
where.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

#: ``struct.Struct(fmt).unpack_from``: reads one big-endian number at an offset.
_Unpack = Callable[[memoryview, int], tuple[Any, ...]]

_U8 = struct.Struct(">B").unpack_from
_U16 = struct.Struct(">H").unpack_from
_U32 = struct.Struct(">I").unpack_from
_U64 = struct.Struct(">Q").unpack_from
_I8 = struct.Struct(">b").unpack_from
_I16 = struct.Struct(">h").unpack_from
_I32 = struct.Struct(">i").unpack_from
_I64 = struct.Struct(">q").unpack_from
_F32 = struct.Struct(">f").unpack_from
_F64 = struct.Struct(">d").unpack_from


class MsgViewError(ValueError):
    """The payload is not valid msgpack within the limits."""


@dataclass(frozen=True)
class Limits:
    """Largest accepted lengths (elements for containers, bytes otherwise) and nesting."""

    max_bin_len: int
    max_str_len: int
    max_array_len: int
    max_map_len: int
    max_depth: int = 32


class _Reader:
    __slots__ = ("lim", "mv", "pos")

    def __init__(self, buf: bytes | bytearray | memoryview, lim: Limits) -> None:
        self.mv = memoryview(buf).cast("B") if not isinstance(buf, bytes) else memoryview(buf)
        self.pos = 0
        self.lim = lim

    def _need(self, n: int, what: str) -> int:
        p = self.pos
        if p + n > len(self.mv):
            raise MsgViewError(f"truncated {what} at byte {p}: needs {n} bytes, {len(self.mv) - p} left")
        self.pos = p + n
        return p

    def _len(self, fmt: _Unpack, size: int, what: str) -> int:
        return fmt(self.mv, self._need(size, what + " length"))[0]

    def _check(self, n: int, limit: int, what: str) -> int:
        if n > limit:
            raise MsgViewError(f"{what} of {n} at byte {self.pos} exceeds the limit of {limit}")
        return n

    def _str(self, n: int) -> str:
        self._check(n, self.lim.max_str_len, "string length")
        p = self._need(n, "string")
        try:
            return str(self.mv[p : p + n], "utf-8")
        except UnicodeDecodeError as exc:
            raise MsgViewError(f"string at byte {p} is not UTF-8 ({exc.reason})") from None

    def _bin(self, n: int) -> memoryview:
        self._check(n, self.lim.max_bin_len, "bin length")
        p = self._need(n, "bin")
        return self.mv[p : p + n].toreadonly()

    def _array(self, n: int, depth: int) -> list[Any]:
        self._check(n, self.lim.max_array_len, "array length")
        return [self.value(depth + 1) for _ in range(n)]

    def _map(self, n: int, depth: int) -> dict[str | bytes, Any]:
        self._check(n, self.lim.max_map_len, "map length")
        out: dict[str | bytes, Any] = {}
        for _ in range(n):
            at = self.pos
            key = self.value(depth + 1)
            if not isinstance(key, (str, memoryview)):
                raise MsgViewError(f"map key at byte {at} must be a string or bytes, got {type(key).__name__}")
            if isinstance(key, memoryview):
                key = key.tobytes()
            out[key] = self.value(depth + 1)
        return out

    def value(self, depth: int = 0) -> Any:  # noqa: PLR0911, PLR0912 - one branch per msgpack type byte, as in the spec
        if depth > self.lim.max_depth:
            raise MsgViewError(f"nesting deeper than {self.lim.max_depth} at byte {self.pos}")
        b = self.mv[self._need(1, "type byte")]
        if b <= 0x7F:
            return b
        if b >= 0xE0:
            return b - 0x100
        if 0xA0 <= b <= 0xBF:
            return self._str(b & 0x1F)
        if 0x80 <= b <= 0x8F:
            return self._map(b & 0x0F, depth)
        if 0x90 <= b <= 0x9F:
            return self._array(b & 0x0F, depth)
        if b == 0xC0:
            return None
        if b == 0xC2:
            return False
        if b == 0xC3:
            return True
        if b == 0xC4:
            return self._bin(self._len(_U8, 1, "bin"))
        if b == 0xC5:
            return self._bin(self._len(_U16, 2, "bin"))
        if b == 0xC6:
            return self._bin(self._len(_U32, 4, "bin"))
        if b == 0xCA:
            return _F32(self.mv, self._need(4, "float32"))[0]
        if b == 0xCB:
            return _F64(self.mv, self._need(8, "float64"))[0]
        if 0xCC <= b <= 0xD3:
            fmt, size = ((_U8, 1), (_U16, 2), (_U32, 4), (_U64, 8), (_I8, 1), (_I16, 2), (_I32, 4), (_I64, 8))[b - 0xCC]
            return fmt(self.mv, self._need(size, "integer"))[0]
        if b == 0xD9:
            return self._str(self._len(_U8, 1, "string"))
        if b == 0xDA:
            return self._str(self._len(_U16, 2, "string"))
        if b == 0xDB:
            return self._str(self._len(_U32, 4, "string"))
        if b == 0xDC:
            return self._array(self._len(_U16, 2, "array"), depth)
        if b == 0xDD:
            return self._array(self._len(_U32, 4, "array"), depth)
        if b == 0xDE:
            return self._map(self._len(_U16, 2, "map"), depth)
        if b == 0xDF:
            return self._map(self._len(_U32, 4, "map"), depth)
        if b == 0xC1:
            raise MsgViewError(f"byte 0xc1 (never used) at byte {self.pos - 1}")
        raise MsgViewError(f"extension type 0x{b:02x} at byte {self.pos - 1} is not accepted")


def loads(payload: bytes | bytearray | memoryview, limits: Limits) -> Any:
    """Decode one msgpack object that spans the whole payload.

    Parameters
    ----------
    payload : bytes-like
        The message. ``bin`` fields are returned as read-only views of it.
    limits : Limits
        Largest accepted lengths and nesting depth.

    Raises
    ------
    MsgViewError
        Malformed, truncated, trailing bytes, over a limit, extension types.
    """
    try:
        r = _Reader(payload, limits)
    except (TypeError, ValueError) as exc:  # e.g. a non-contiguous memoryview
        raise MsgViewError(f"payload is not a contiguous byte buffer ({exc})") from None
    out = r.value()
    if r.pos != len(r.mv):
        raise MsgViewError(f"{len(r.mv) - r.pos} trailing bytes after the object at byte {r.pos}")
    return out


__all__ = ["Limits", "MsgViewError", "loads"]
