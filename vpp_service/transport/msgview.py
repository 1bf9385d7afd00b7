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
or strings longer than the given limits, nesting deeper than ``max_depth`` and
more than ``max_elements`` objects in all (every scalar, string, bin, array
and map counts once, however deeply nested: one bound on the work a message
can cause). With ``keep``, the values of top-level keys outside it are skipped
(walked to find their end, counted, but never built into Python objects).
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
#: Reader and size of each integer type byte 0xcc..0xd3 (uint8..uint64, int8..int64).
_INTS = ((_U8, 1), (_U16, 2), (_U32, 4), (_U64, 8), (_I8, 1), (_I16, 2), (_I32, 4), (_I64, 8))


class MsgViewError(ValueError):
    """The payload is not valid msgpack within the limits."""


@dataclass(frozen=True)
class Limits:
    """Largest accepted lengths (elements for containers, bytes otherwise), nesting and total object count."""

    max_bin_len: int
    max_str_len: int
    max_array_len: int
    max_map_len: int
    max_depth: int = 32
    max_elements: int = 1 << 20


class _Reader:
    __slots__ = ("left", "lim", "max_depth", "max_str_len", "mv", "pos")

    def __init__(self, buf: bytes | bytearray | memoryview, lim: Limits) -> None:
        self.mv = memoryview(buf).cast("B") if not isinstance(buf, bytes) else memoryview(buf)
        self.pos = 0
        self.lim = lim
        self.left = lim.max_elements  # objects still allowed in this message
        self.max_depth, self.max_str_len = lim.max_depth, lim.max_str_len  # read once per object: kept at hand

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
        if n > self.max_str_len:
            self._check(n, self.max_str_len, "string length")
        p = self.pos
        if p + n > len(self.mv):
            self._need(n, "string")
        self.pos = p + n
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
        if n > self.left:  # a header alone cannot claim more work than the budget allows
            raise MsgViewError(f"array of {n} objects at byte {self.pos} exceeds the element limit")
        return [self.value(depth + 1) for _ in range(n)]

    def _map(self, n: int, depth: int, keep: frozenset[str] | None = None) -> dict[str | bytes, Any]:
        self._check(n, self.lim.max_map_len, "map length")
        if 2 * n > self.left:  # a header alone cannot claim more work than the budget allows
            raise MsgViewError(f"map of {n} entries at byte {self.pos} exceeds the element limit")
        out: dict[str | bytes, Any] = {}
        for _ in range(n):
            at = self.pos
            key = self.value(depth + 1)
            if not isinstance(key, (str, memoryview)):
                raise MsgViewError(f"map key at byte {at} must be a string or bytes, got {type(key).__name__}")
            if isinstance(key, memoryview):
                key = key.tobytes()
            if keep is not None and key not in keep:
                self.skip(depth + 1)
            else:
                out[key] = self.value(depth + 1)
        return out

    def skip(self, depth: int) -> None:  # noqa: PLR0912 - one branch per msgpack type family
        """Walk past one object without building it (well-formedness, limits and element count still checked)."""
        depths = [depth]  # nesting depth of every object still to walk past (a stack: no recursion)
        while depths:
            d = depths.pop()
            if d > self.lim.max_depth:
                raise MsgViewError(f"nesting deeper than {self.lim.max_depth} at byte {self.pos}")
            self.left -= 1
            if self.left < 0:
                raise MsgViewError(f"more than {self.lim.max_elements} objects (at byte {self.pos})")
            b = self.mv[self._need(1, "type byte")]
            n = 0  # children of a container
            if b <= 0x7F or b >= 0xE0 or b in (0xC0, 0xC2, 0xC3):
                continue
            if 0xA0 <= b <= 0xBF:
                self._need(self._check(b & 0x1F, self.lim.max_str_len, "string length"), "string")
                continue
            if 0x80 <= b <= 0x8F:
                n = 2 * self._check(b & 0x0F, self.lim.max_map_len, "map length")
            elif 0x90 <= b <= 0x9F:
                n = b & 0x0F
            elif b in (0xC4, 0xC5, 0xC6):
                size = 1 << (b - 0xC4)
                ln = self._len((_U8, _U16, _U32)[b - 0xC4], size, "bin")
                self._need(self._check(ln, self.lim.max_bin_len, "bin length"), "bin")
                continue
            elif b in (0xD9, 0xDA, 0xDB):
                ln = self._len((_U8, _U16, _U32)[b - 0xD9], 1 << (b - 0xD9), "string")
                self._need(self._check(ln, self.lim.max_str_len, "string length"), "string")
                continue
            elif b in (0xCA, 0xCB):
                self._need(4 if b == 0xCA else 8, "float")
                continue
            elif 0xCC <= b <= 0xD3:
                self._need((1, 2, 4, 8)[(b - 0xCC) % 4], "integer")
                continue
            elif b in (0xDC, 0xDD):
                ln = self._len(_U16 if b == 0xDC else _U32, 2 if b == 0xDC else 4, "array")
                n = self._check(ln, self.lim.max_array_len, "array length")
            elif b in (0xDE, 0xDF):
                ln = self._len(_U16 if b == 0xDE else _U32, 2 if b == 0xDE else 4, "map")
                n = 2 * self._check(ln, self.lim.max_map_len, "map length")
            elif b == 0xC1:
                raise MsgViewError(f"byte 0xc1 (never used) at byte {self.pos - 1}")
            else:
                raise MsgViewError(f"extension type 0x{b:02x} at byte {self.pos - 1} is not accepted")
            if n > self.left:
                raise MsgViewError(f"container of {n} objects at byte {self.pos} exceeds the element limit")
            depths.extend([d + 1] * n)

    def value(self, depth: int = 0, keep: frozenset[str] | None = None) -> Any:  # noqa: PLR0911, PLR0912 - one branch per type byte
        if depth > self.max_depth:
            raise MsgViewError(f"nesting deeper than {self.max_depth} at byte {self.pos}")
        self.left -= 1
        if self.left < 0:
            raise MsgViewError(f"more than {self.lim.max_elements} objects (at byte {self.pos})")
        p = self.pos  # the type byte, read inline: this runs once per object (the hot path of every message)
        if p >= len(self.mv):
            self._need(1, "type byte")
        self.pos = p + 1
        b = self.mv[p]
        if b <= 0x7F:
            return b
        if 0xA0 <= b <= 0xBF:  # fixstr (map keys): before the rarer negative fixint
            return self._str(b & 0x1F)
        if b >= 0xE0:
            return b - 0x100
        if 0x80 <= b <= 0x8F:
            return self._map(b & 0x0F, depth, keep)
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
            fmt, size = _INTS[b - 0xCC]
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
            return self._map(self._len(_U16, 2, "map"), depth, keep)
        if b == 0xDF:
            return self._map(self._len(_U32, 4, "map"), depth, keep)
        if b == 0xC1:
            raise MsgViewError(f"byte 0xc1 (never used) at byte {self.pos - 1}")
        raise MsgViewError(f"extension type 0x{b:02x} at byte {self.pos - 1} is not accepted")


def loads(payload: bytes | bytearray | memoryview, limits: Limits, keep: frozenset[str] | None = None) -> Any:
    """Decode one msgpack object that spans the whole payload.

    Parameters
    ----------
    payload : bytes-like
        The message. ``bin`` fields are returned as read-only views of it.
    limits : Limits
        Largest accepted lengths, nesting depth and total object count.
    keep : frozenset of str, optional
        When the object is a map, only these keys are decoded; the values of
        the others are skipped (still checked for well-formedness and limits)
        and left out of the result.

    Raises
    ------
    MsgViewError
        Malformed, truncated, trailing bytes, over a limit, extension types.
    """
    try:
        r = _Reader(payload, limits)
    except (TypeError, ValueError) as exc:  # e.g. a non-contiguous memoryview
        raise MsgViewError(f"payload is not a contiguous byte buffer ({exc})") from None
    out = r.value(keep=keep)
    if r.pos != len(r.mv):
        raise MsgViewError(f"{len(r.mv) - r.pos} trailing bytes after the object at byte {r.pos}")
    return out


__all__ = ["Limits", "MsgViewError", "loads"]
