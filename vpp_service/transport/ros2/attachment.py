"""The attachment every ``rmw_zenoh`` sample carries: sequence number, source timestamp, publisher gid.

A ROS subscriber drops a sample without one and aborts on a malformed one, so every
sample we publish has one, and every one we receive is checked before its payload.

Two layouts exist (little endian; they must not be mixed on one graph):

``current`` (Jazzy >= 0.2.4, Kilted, Rolling >= 0.6.0, Humble >= 0.1.2), 33 bytes::

    int64 sequence_number | int64 source_timestamp_ns | 0x10 | 16-byte gid

``legacy`` (Jazzy 0.2.0 - 0.2.3), 77 bytes: each field preceded by its name as a
length-prefixed string::

    0x0f "sequence_number" int64 | 0x10 "source_timestamp" int64 | 0x0a "source_gid" 0x10 gid
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Literal

from vpp_service.transport.ros2.errors import Ros2Error

#: Attachment layouts, see the module docstring.
Layout = Literal["current", "legacy"]
#: Size of a publisher gid in bytes.
GID_SIZE = 16
#: Size of a ``current`` attachment.
CURRENT_SIZE = 8 + 8 + 1 + GID_SIZE

_I64 = struct.Struct("<q")
_LABELS = (b"sequence_number", b"source_timestamp", b"source_gid")
_LEGACY_SIZE = sum(1 + len(label) for label in _LABELS) + 8 + 8 + 1 + GID_SIZE


@dataclass(frozen=True)
class Attachment:
    """One sample's attachment.

    Attributes
    ----------
    sequence_number : int
        Per-publisher counter, from 1.
    source_timestamp_ns : int
        Publication time, system clock, ns.
    gid : bytes
        16-byte publisher id.
    """

    sequence_number: int
    source_timestamp_ns: int
    gid: bytes

    def __post_init__(self) -> None:
        for name in ("sequence_number", "source_timestamp_ns"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or not -(2**63) <= v < 2**63:
                raise ValueError(f"{name} must be a signed 64-bit integer, got {v!r}")
        if not isinstance(self.gid, bytes) or len(self.gid) != GID_SIZE:
            raise ValueError(f"gid must be {GID_SIZE} bytes, got {self.gid!r}")


def encode(att: Attachment, layout: Layout = "current") -> bytes:
    """The attachment bytes in ``layout`` (33 bytes ``current``, 77 bytes ``legacy``)."""
    seq, ts = _I64.pack(att.sequence_number), _I64.pack(att.source_timestamp_ns)
    gid = bytes([GID_SIZE]) + att.gid
    if layout == "current":
        return seq + ts + gid
    if layout == "legacy":
        seq_l, ts_l, gid_l = (bytes([len(label)]) + label for label in _LABELS)
        return seq_l + seq + ts_l + ts + gid_l + gid
    raise ValueError(f"layout must be 'current' or 'legacy', got {layout!r}")


def decode(data: bytes | bytearray | memoryview | None) -> tuple[Attachment, Layout]:
    """Parse either layout; returns the attachment and which layout it was.

    Raises
    ------
    Ros2Error
        ``attachment``: missing, wrong size, wrong labels or gid length.
    """
    if data is None:
        raise Ros2Error("attachment", "missing (rmw_zenoh samples always carry one)")
    b = bytes(data[: _LEGACY_SIZE + 1])
    if len(b) == CURRENT_SIZE and b[16] == GID_SIZE:
        return Attachment(_I64.unpack_from(b, 0)[0], _I64.unpack_from(b, 8)[0], b[17:]), "current"
    if len(b) == _LEGACY_SIZE and b[0] == len(_LABELS[0]):
        pos, values = 0, []
        for label, size in zip(_LABELS, (8, 8, 1 + GID_SIZE), strict=True):
            end = pos + 1 + len(label)
            if b[pos] != len(label) or b[pos + 1 : end] != label:
                raise Ros2Error("attachment", f"legacy layout: expected field {label.decode()!r} at byte {pos}")
            values.append(b[end : end + size])
            pos = end + size
        if values[2][0] != GID_SIZE:
            raise Ros2Error("attachment", f"legacy layout: gid length {values[2][0]}, expected {GID_SIZE}")
        seq, ts = _I64.unpack(values[0])[0], _I64.unpack(values[1])[0]
        return Attachment(seq, ts, values[2][1:]), "legacy"
    raise Ros2Error(
        "attachment", f"{len(data)} bytes: neither the {CURRENT_SIZE}-byte nor the {_LEGACY_SIZE}-byte layout"
    )


__all__ = ["CURRENT_SIZE", "GID_SIZE", "Attachment", "Layout", "decode", "encode"]
