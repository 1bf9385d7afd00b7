"""PNG and JPEG streams from untrusted senders: read the header, check the stream, then decode.

Both the msgpack wire format (:mod:`vpp_service.transport.wire`) and ROS 2's
``sensor_msgs/CompressedImage`` (:mod:`vpp_service.transport.ros2.messages`) carry encoded
images from the network. A decoder allocates what the stream's header declares, so a
hostile header (a "decompression bomb": a few bytes declaring 100000 x 100000 pixels) must
be read and bounded first. :func:`probe` reads the declared size and channel count
without decoding (the PNG ``IHDR``, the JPEG frame header ``SOFn``, with bounded scans);
:func:`check_stream` then walks the stream's structure so that a truncated or corrupted
one is refused here, with a message naming the problem, instead of by libpng / libjpeg,
which report it on stderr past any log rate limit; only then is the stream decoded.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass
from typing import Literal

import numpy as np

#: A stream as a decoder receives it (a msgpack ``bin``, a ROS message's ``uint8[]``).
Binary = bytes | bytearray | memoryview | np.ndarray

#: The two encodings: PNG (lossless) and JPEG (baseline or progressive).
Codec = Literal["png", "jpeg"]

#: Chunks a PNG stream may have (bounds the structure walk of a hostile stream; OpenCV writes 8 KiB IDAT chunks).
PNG_MAX_CHUNKS = 1 << 16
#: Markers scanned for a JPEG frame header before giving up (bounds the header scan of a hostile stream).
JPEG_MAX_MARKERS = 1024
#: Zero bytes a JPEG stream may carry after its end-of-image marker (some cameras pad to a word size).
JPEG_MAX_PADDING = 4096

_PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
_JPEG_MAGIC = b"\xff\xd8"
#: PNG colour types (IHDR byte 9) -> channels: grey, RGB, palette, grey + alpha, RGBA.
_PNG_CHANNELS = {0: 1, 2: 3, 3: 3, 4: 2, 6: 4}


class EncodedImageError(ValueError):
    """An encoded image is refused: not PNG/JPEG, truncated, corrupt or over a limit (the message says which)."""


class TooLargeError(EncodedImageError):
    """The stream's header declares more pixels than allowed (a decompression bomb, or just too big)."""


@dataclass(frozen=True)
class StreamHeader:
    """What an encoded stream declares, read before any decoding.

    Attributes
    ----------
    codec : {"png", "jpeg"}
        The stream's format (from its magic bytes).
    height, width : int
        Declared size in pixels.
    channels : int
        Declared components: 1 (grey), 2 (grey + alpha), 3 (colour) or 4 (colour + alpha).
    bit_depth : int
        Bits per sample (8 or 16 for PNG, 8 or 12 for JPEG).
    """

    codec: Codec
    height: int
    width: int
    channels: int
    bit_depth: int


def sniff(data: Binary) -> Codec:
    """The codec of ``data`` from its magic bytes.

    Raises
    ------
    EncodedImageError
        Neither a PNG nor a JPEG stream.
    """
    head = bytes(data[:8])
    if head == _PNG_MAGIC:
        return "png"
    if head[:2] == _JPEG_MAGIC:
        return "jpeg"
    raise EncodedImageError(f"not a PNG or JPEG stream (starts with {head[:4].hex() or 'nothing'})")


def png_size(data: Binary) -> tuple[int, int]:
    """``(height, width)`` declared by a PNG's ``IHDR`` chunk.

    Raises
    ------
    EncodedImageError
        Not a PNG stream.
    """
    return _png_header(data)[:2]


def _png_header(data: Binary) -> tuple[int, int, int, int]:
    """``(height, width, channels, bit_depth)`` of the ``IHDR`` chunk."""
    if len(data) < 26 or bytes(data[:8]) != _PNG_MAGIC or bytes(data[12:16]) != b"IHDR":
        raise EncodedImageError("not a PNG stream")
    w, h = struct.unpack(">II", bytes(data[16:24]))
    depth, colour = int(data[24]), int(data[25])
    if colour not in _PNG_CHANNELS:
        raise EncodedImageError(f"PNG colour type {colour} is not a valid one")
    return h, w, _PNG_CHANNELS[colour], depth


def png_check(data: Binary) -> None:
    """Walk the PNG chunks: every CRC right, IDAT present, IEND last (before libpng sees the stream).

    Raises
    ------
    EncodedImageError
        Truncated, a bad CRC, no image data, bytes after ``IEND`` or more than
        :data:`PNG_MAX_CHUNKS` chunks.
    """
    mv = np.frombuffer(data, np.uint8).data  # one byte an item, whatever buffer came
    i, n, idat = 8, len(mv), False
    for _ in range(PNG_MAX_CHUNKS):
        if i + 12 > n:
            raise EncodedImageError("truncated PNG stream")
        length = int.from_bytes(mv[i : i + 4], "big")
        end = i + 12 + length
        if end > n:
            raise EncodedImageError("truncated PNG stream")
        kind = bytes(mv[i + 4 : i + 8])
        if zlib.crc32(mv[i + 4 : i + 8 + length]) != int.from_bytes(mv[i + 8 + length : end], "big"):
            raise EncodedImageError(f"corrupt PNG stream (bad CRC of chunk {kind!r})")
        idat = idat or kind == b"IDAT"
        if kind == b"IEND":
            if end != n or not idat:
                raise EncodedImageError("PNG stream without image data or with bytes after IEND")
            return
        i = end
    raise EncodedImageError(f"PNG stream of more than {PNG_MAX_CHUNKS} chunks")


def jpeg_size(data: Binary) -> tuple[int, int]:
    """``(height, width)`` declared by a JPEG's frame header.

    Raises
    ------
    EncodedImageError
        Not a JPEG stream, a corrupt marker, or no frame header within :data:`JPEG_MAX_MARKERS` markers.
    """
    return _jpeg_header(data)[:2]


def _jpeg_header(data: Binary) -> tuple[int, int, int, int]:
    """``(height, width, components, precision)`` of the first frame header (``SOFn``)."""
    if len(data) < 4 or bytes(data[:2]) != _JPEG_MAGIC:
        raise EncodedImageError("not a JPEG stream")
    i = 2
    steps = 0
    while i + 4 <= len(data):
        steps += 1
        if steps > JPEG_MAX_MARKERS:  # real streams reach their frame header within a few dozen
            raise EncodedImageError(f"no JPEG frame header within {JPEG_MAX_MARKERS} markers")
        if data[i] != 0xFF:
            raise EncodedImageError("corrupt JPEG marker")
        marker = data[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        if marker in (0xD8, 0x01) or 0xD0 <= marker <= 0xD7:
            i += 2
            continue
        seg = struct.unpack(">H", bytes(data[i + 2 : i + 4]))[0]
        if 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):
            if i + 10 > len(data):
                break
            precision = int(data[i + 4])
            h, w = struct.unpack(">HH", bytes(data[i + 5 : i + 9]))
            return h, w, int(data[i + 9]), precision
        i += 2 + seg
    raise EncodedImageError("JPEG without a frame header")


def jpeg_check(data: Binary) -> None:
    """A JPEG stream must end with its end-of-image marker (``FF D9``, then at most zero padding).

    A stream cut short (a dropped packet, a recorder killed) lacks it; libjpeg would fill the
    missing rows with grey and warn on stderr.

    Raises
    ------
    EncodedImageError
        The marker is missing.
    """
    tail = np.frombuffer(data, np.uint8)[-(JPEG_MAX_PADDING + 2) :]
    nonzero = np.flatnonzero(tail)
    end = int(nonzero[-1]) + 1 if nonzero.size else 0
    if end < 2 or tail[end - 2] != 0xFF or tail[end - 1] != 0xD9:
        raise EncodedImageError("truncated JPEG stream (no end-of-image marker)")


def probe(data: Binary, max_pixels: int) -> StreamHeader:
    """The header of a PNG or JPEG stream, its size bounded by ``max_pixels``, before any decoding.

    Raises
    ------
    EncodedImageError
        Not PNG/JPEG, a header that cannot be read, an empty size, or more than ``max_pixels`` pixels
        (:class:`TooLargeError`, naming the declared size: a decompression bomb is refused here).
    """
    codec = sniff(data)
    h, w, channels, depth = _png_header(data) if codec == "png" else _jpeg_header(data)
    if h < 1 or w < 1:
        raise EncodedImageError(f"{codec.upper()} stream declares an empty image ({w}x{h})")
    if h * w > max_pixels:
        raise TooLargeError(f"{codec.upper()} stream declares {w}x{h} = {h * w} pixels > max {max_pixels}")
    return StreamHeader(codec, h, w, channels, depth)


def check_stream(data: Binary, codec: Codec) -> None:
    """The structure check of ``codec`` (:func:`png_check` or :func:`jpeg_check`)."""
    if codec == "png":
        png_check(data)
    else:
        jpeg_check(data)


def decode(data: Binary, header: StreamHeader, grey: bool) -> np.ndarray:
    """Decode a probed and checked stream: H x W uint8 (``grey``) or H x W x 3 uint8 RGB.

    16-bit PNG samples are scaled to 8 bits by ``v / 257`` (rounded: the full 16-bit range to
    the full 8-bit range, as ``mono16`` images are); an alpha channel is dropped.

    Raises
    ------
    EncodedImageError
        The decoder refused the stream, or it decoded to another size than its header declared.
    """
    import cv2

    flag = (cv2.IMREAD_GRAYSCALE if grey else cv2.IMREAD_COLOR) | cv2.IMREAD_ANYDEPTH
    out = cv2.imdecode(np.frombuffer(data, np.uint8), flag)
    if out is None or out.shape[:2] != (header.height, header.width):
        raise EncodedImageError(f"could not decode the {header.codec.upper()} stream (corrupt data)")
    if out.dtype == np.uint16:
        out = ((out.astype(np.uint32) * 255 + 32767) // 65535).astype(np.uint8)
    return out if grey else cv2.cvtColor(out, cv2.COLOR_BGR2RGB)


__all__ = [
    "JPEG_MAX_MARKERS",
    "JPEG_MAX_PADDING",
    "PNG_MAX_CHUNKS",
    "Binary",
    "Codec",
    "EncodedImageError",
    "StreamHeader",
    "TooLargeError",
    "check_stream",
    "decode",
    "jpeg_check",
    "jpeg_size",
    "png_check",
    "png_size",
    "probe",
    "sniff",
]
