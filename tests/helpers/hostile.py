"""Hostile ``in/frame`` messages: what a peer on the network could send to the service.

Used by the test suite and by ``benchmarks/soak.py``. Every kind is a message the
service must reject (and count) quickly and without a memory spike: malformed
msgpack, caps on message bytes / element count / nesting / pixels, lying image
headers, out-of-range depth, and rig names that would escape a sink's folder or
belong to another rig. :func:`hostile_message` builds one message of a kind;
:data:`KINDS` lists them all.
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Callable

import msgpack
import numpy as np

from helpers.frames import make_frame
from vpp_service.frame import StereoFrame
from vpp_service.transport import wire

#: Where each kind is expected to be stopped: ``"wire"`` (decoding raises WireError),
#: ``"rig"`` (decodes, but the pipeline rejects a rig it does not serve), ``"size"`` (over the
#: message-size cap: rejected by length before unpacking).
Stage = str


def _frame(rig: str = "rig0", seq: int = 0, h: int = 12, w: int = 16) -> StereoFrame:
    return make_frame(h=h, w=w, seed=seq).with_(rig=rig, seq=seq)


def valid_message(rig: str = "rig0", seq: int = 0, stamp_ns: int = 123456789, h: int = 12, w: int = 16) -> bytes:
    """A small valid ``in/frame`` message (``h`` x ``w`` RGB, metric points, ground truth)."""
    return wire.encode_frame(_frame(rig, seq, h, w).with_(stamp_ns=stamp_ns))


def _fields(seq: int) -> dict[str, object]:
    out: dict[str, object] = msgpack.unpackb(valid_message(seq=seq), raw=False)
    return out


def _pack(msg: object) -> bytes:
    data: bytes = msgpack.packb(msg, use_bin_type=True)
    return data


def _png_header(h: int, w: int) -> bytes:
    """The first bytes of a PNG declaring ``w`` x ``h`` RGB (signature + IHDR), then a short, corrupt IDAT."""
    ihdr = struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)
    chunk = b"IHDR" + ihdr
    out = b"\x89PNG\r\n\x1a\n" + struct.pack(">I", len(ihdr)) + chunk + struct.pack(">I", zlib.crc32(chunk))
    idat = b"IDAT" + zlib.compress(b"\0" * 1024)[:40]
    return out + struct.pack(">I", len(idat) - 4) + idat + struct.pack(">I", zlib.crc32(idat))


def _chunk(kind: bytes, body: bytes) -> bytes:
    return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))


def png_bomb(width: int, height: int) -> bytes:
    """A complete, valid PNG of ``width`` x ``height`` black 1-bit pixels: 20000 x 20000 is ~40 KiB on the wire.

    Every chunk and CRC is right, so only a bound on the declared size stops a decoder from
    allocating the whole image (400 M pixels, 1.2 GB as an 8-bit colour image).
    """
    row = b"\0" * (1 + (width + 7) // 8)  # filter byte "none", then the packed bits
    z = zlib.compressobj(9)
    idat = b"".join(z.compress(row) for _ in range(height)) + z.flush()
    ihdr = struct.pack(">IIBBBBB", width, height, 1, 0, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr) + _chunk(b"IDAT", idat) + _chunk(b"IEND", b"")


def _with_image(seq: int, **image: object) -> bytes:
    msg = _fields(seq)
    left = dict(msg["left"])  # type: ignore[call-overload]
    left.update(image)
    msg["left"] = left
    msg["right"] = left
    return _pack(msg)


def _empty_maps(n: int) -> bytes:
    """An array of arrays holding ``n`` empty maps in all (one byte each), no container over 60000 long."""
    chunks = [min(60000, n - i) for i in range(0, n, 60000)]
    return (
        b"\xdd"
        + struct.pack(">I", len(chunks))
        + b"".join(b"\xdd" + struct.pack(">I", c) + b"\x80" * c for c in chunks)
    )


def _nested_maps(n: int) -> bytes:
    # {"v": 1, "junk": [[{}, {}, ...], ...]} built by hand
    return b"\x82" + _pack("v") + b"\x01" + _pack("junk") + _empty_maps(n)


def _unknown_key_nested(n: int, seq: int) -> bytes:
    # a valid frame plus one unknown key holding n nested empty maps: rejected by the element cap
    good = valid_message(seq=seq)
    count = good[0] & 0x0F
    return bytes([0x80 | (count + 1)]) + good[1:] + _pack("x-extension") + _empty_maps(n)


def _small_containers(n: int) -> bytes:
    # {"v": 1, "junk": [[{} x 15] x n]}: no container is long, the total is what is large
    return (
        b"\x82" + _pack("v") + b"\x01" + _pack("junk") + b"\xdd" + struct.pack(">I", n) + (b"\x9f" + b"\x80" * 15) * n
    )


def _encoded(seq: int, enc: str) -> bytes:
    """A real PNG/JPEG of the frame's left image, with one byte in the middle of its data flipped."""
    img = _frame(seq=seq).left
    encoded = wire.encode_image(img, enc)["data"]
    assert isinstance(encoded, bytes)
    data = bytearray(encoded)
    data[len(data) // 2] ^= 0x5A
    return bytes(data)


def _deep_nesting(depth: int) -> bytes:
    return b"\x91" * depth + b"\xc0"


def _jpeg_marker_flood(n: int) -> bytes:
    return b"\xff\xd8" + b"\xff\xe1\x00\x02" * n + b"\xff\xd9"


def _oversize(max_message_bytes: int) -> bytes:
    msg = _fields(0)
    msg["pad"] = b"\0" * (max_message_bytes + 1)
    return _pack(msg)


#: kind -> (stage that must stop it, builder(seq, max_message_bytes) -> payload)
KINDS: dict[str, tuple[Stage, Callable[[int, int], bytes]]] = {
    "oversize": ("size", lambda seq, cap: _oversize(cap)),
    "nested_empty_maps": ("wire", lambda seq, cap: _nested_maps(min(cap - 4096, 16 << 20))),
    "unknown_key_nested": ("wire", lambda seq, cap: _unknown_key_nested(min(cap - 8192, 16 << 20), seq)),
    "array_header_lies": ("wire", lambda seq, cap: b"\x81\xa4junk\xdd\xff\xff\xff\xff"),
    "many_small_containers": ("wire", lambda seq, cap: _small_containers(min((cap - 4096) // 16, 60000))),
    "png_bad_crc": ("wire", lambda seq, cap: _with_image(seq, h=12, w=16, c=3, enc="png", data=_encoded(seq, "png"))),
    "jpeg_corrupt": (
        "wire",
        lambda seq, cap: _with_image(seq, h=12, w=16, c=3, enc="jpeg", data=_encoded(seq, "jpeg")[:200]),
    ),
    "deep_nesting": ("wire", lambda seq, cap: _deep_nesting(10000)),
    "truncated": ("wire", lambda seq, cap: valid_message(seq=seq)[:-9]),
    "random_bytes": ("wire", lambda seq, cap: np.random.default_rng(seq).bytes(4096)),
    "top_level_array": ("wire", lambda seq, cap: _pack([1, 2, 3])),
    "extension_type": ("wire", lambda seq, cap: b"\x81\xa1v\xd4\x01\x00"),
    "wrong_version": ("wire", lambda seq, cap: _pack({**_fields(seq), "v": 99})),
    "png_bomb": (
        "wire",
        lambda seq, cap: _with_image(seq, h=8192, w=8192, c=3, enc="png", data=_png_header(8192, 8192)),
    ),
    "png_header_lies": (
        "wire",
        lambda seq, cap: _with_image(seq, h=12, w=16, c=3, enc="png", data=_png_header(4000, 4000)),
    ),
    "png_corrupt_data": (
        "wire",
        lambda seq, cap: _with_image(seq, h=12, w=16, c=3, enc="png", data=_png_header(12, 16)),
    ),
    "jpeg_marker_flood": (
        "wire",
        lambda seq, cap: _with_image(
            seq, h=12, w=16, c=3, enc="jpeg", data=_jpeg_marker_flood(min(cap // 16, 1 << 20))
        ),
    ),
    "raw_declared_huge": ("wire", lambda seq, cap: _with_image(seq, h=16384, w=16384, c=3, enc="raw", data=b"\0" * 64)),
    "raw_length_mismatch": ("wire", lambda seq, cap: _with_image(seq, h=12, w=16, c=3, enc="raw", data=b"\0" * 7)),
    "depth_points_outside": (
        "wire",
        lambda seq, cap: _pack(
            {
                **_fields(seq),
                "depth": {
                    "kind": "points",
                    "n": 1,
                    "uv": np.array([1e6, 1e6], "<f4").tobytes(),
                    "z": np.array([1.0], "<f4").tobytes(),
                },
            }
        ),
    ),
    "depth_map_huge": (
        "wire",
        lambda seq, cap: _pack(
            {**_fields(seq), "depth": {"kind": "map", "h": 16384, "w": 16384, "unit": "m", "data": b""}}
        ),
    ),
    "calib_not_finite": (
        "wire",
        lambda seq, cap: _pack({**_fields(seq), "calib": {"f": float("nan"), "baseline": 0.1}}),
    ),
    "seq_wrong_type": ("wire", lambda seq, cap: _pack({**_fields(seq), "seq": "seven"})),
    "rig_traversal": ("rig", lambda seq, cap: valid_message("../../x/relative", seq)),
    "rig_absolute": ("rig", lambda seq, cap: valid_message("/tmp/vpp-hostile-abs", seq)),
    "rig_hidden": ("rig", lambda seq, cap: valid_message(".hidden", seq)),
    "rig_nul": ("rig", lambda seq, cap: valid_message("rig0\x00x", seq)),
    "rig_foreign": ("rig", lambda seq, cap: valid_message("rig1", seq)),
}


def hostile_message(kind: str, seq: int = 0, max_message_bytes: int = wire.DEFAULT_LIMITS.max_message_bytes) -> bytes:
    """One hostile message of ``kind`` (see :data:`KINDS`) for a service serving ``rig0``.

    ``max_message_bytes`` is the cap the receiver applies (``oversize`` is one byte
    past it; the flood kinds are sized to stay under it).
    """
    return KINDS[kind][1](seq, max_message_bytes)


def stage(kind: str) -> Stage:
    """Where ``kind`` must be stopped: ``"size"``, ``"wire"`` or ``"rig"``."""
    return KINDS[kind][0]


__all__ = ["KINDS", "hostile_message", "png_bomb", "stage", "valid_message"]
