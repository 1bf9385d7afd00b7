"""PNG / JPEG streams from the network: header read and bounded before decoding, structure checked, then decoded."""

from __future__ import annotations

import struct
import zlib

import cv2
import numpy as np
import pytest

from helpers.hostile import png_bomb
from vpp_service.transport import encoded_image as ei


def smooth_rgb(h: int = 48, w: int = 64, seed: int = 0) -> np.ndarray:
    """Random colours at 1/8 resolution, upsampled: smooth, as a camera's picture is at the pixel scale."""
    rng = np.random.default_rng(seed)
    return cv2.resize(rng.integers(0, 256, (h // 8, w // 8, 3), dtype=np.uint8), (w, h), interpolation=cv2.INTER_CUBIC)


def encode(img: np.ndarray, ext: str, quality: int = 95) -> bytes:
    bgr = img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_RGB2BGR)
    params = [cv2.IMWRITE_JPEG_QUALITY, quality] if ext == ".jpg" else []
    ok, buf = cv2.imencode(ext, bgr, params)
    assert ok
    return buf.tobytes()


@pytest.mark.parametrize(
    ("ext", "grey", "codec", "channels"),
    [(".png", False, "png", 3), (".png", True, "png", 1), (".jpg", False, "jpeg", 3), (".jpg", True, "jpeg", 1)],
)
def test_probe_reads_the_declared_size_and_channels(ext, grey, codec, channels):
    img = smooth_rgb(30, 50)
    data = encode(img[:, :, 1].copy() if grey else img, ext)
    header = ei.probe(data, max_pixels=30 * 50)
    assert (header.codec, header.height, header.width) == (codec, 30, 50)
    assert (header.channels, header.bit_depth) == (channels, 8)
    with pytest.raises(ei.TooLargeError, match="declares 50x30 = 1500 pixels > max 1499"):
        ei.probe(data, max_pixels=1499)


@pytest.mark.parametrize("ext", [".png", ".jpg"])
def test_decode_after_checks(ext):
    img = smooth_rgb()
    data = encode(img, ext)
    header = ei.probe(data, 1 << 20)
    ei.check_stream(data, header.codec)
    got = ei.decode(data, header, grey=False)
    assert got.shape == img.shape and got.dtype == np.uint8
    err = np.abs(got.astype(int) - img.astype(int))
    assert err.max() == 0 if ext == ".png" else err.mean() < 4.0  # RGB order kept; JPEG q95 close (4:2:0 chroma)
    assert np.abs(got.astype(int) - img[:, :, ::-1].astype(int)).mean() > 20.0  # and red is not blue
    grey = ei.decode(data, header, grey=True)
    assert grey.shape == img.shape[:2]


def test_png_bomb_refused_by_its_header():
    data = png_bomb(20000, 20000)  # a valid 40 KiB stream that inflates to 400 M pixels
    assert len(data) < 100_000
    with pytest.raises(ei.TooLargeError, match="PNG stream declares 20000x20000 = 400000000 pixels > max 8388608"):
        ei.probe(data, 8 * 1024 * 1024)
    ei.png_check(data)  # the stream itself is well-formed: only the limit stops it
    small = png_bomb(64, 32)
    header = ei.probe(small, 8 * 1024 * 1024)
    assert (header.height, header.width, header.channels, header.bit_depth) == (32, 64, 1, 1)
    assert (ei.decode(small, header, grey=True) == 0).all()


def test_truncated_jpeg_named_and_padded_jpeg_accepted():
    data = encode(smooth_rgb(), ".jpg")
    for cut in (len(data) // 2, len(data) - 1):
        with pytest.raises(ei.EncodedImageError, match="truncated JPEG stream"):
            ei.check_stream(data[:cut], "jpeg")
    ei.check_stream(data + bytes(16), "jpeg")  # zero padding after the end-of-image marker
    with pytest.raises(ei.EncodedImageError, match="truncated JPEG stream"):
        ei.check_stream(data + b"\x01", "jpeg")


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda d: d[: len(d) // 2], "truncated PNG stream"),
        (lambda d: d[:40] + bytes([d[40] ^ 0xFF]) + d[41:], "bad CRC"),
        (lambda d: d + b"junk", "bytes after IEND"),
    ],
)
def test_damaged_png_named(mutate, message):
    data = mutate(encode(smooth_rgb(), ".png"))
    with pytest.raises(ei.EncodedImageError, match=message):
        ei.check_stream(data, "png")


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (b"GIF89a......", "not a PNG or JPEG stream"),
        (b"", "not a PNG or JPEG stream"),
        (b"\xff\xd8" + b"\xff\xe0\x00\x04ab" * 1100, "no JPEG frame header within 1024 markers"),
        (b"\xff\xd8\xff\xd9", "JPEG without a frame header"),
    ],
)
def test_not_an_image_named(data, message):
    with pytest.raises(ei.EncodedImageError, match=message):
        ei.probe(data, 1 << 20)


def test_sixteen_bit_png_scaled_like_mono16():
    v = np.array([[0, 257, 65535, 32768]], np.uint16)
    ok, buf = cv2.imencode(".png", v)
    assert ok
    header = ei.probe(buf.tobytes(), 16)
    assert header.bit_depth == 16
    np.testing.assert_array_equal(ei.decode(buf.tobytes(), header, grey=True), [[0, 1, 255, 128]])


def test_corrupt_scan_data_that_the_decoder_refuses():
    data = bytearray(encode(smooth_rgb(), ".png"))
    header = ei.probe(bytes(data), 1 << 20)
    idat = data.index(b"IDAT")
    data[idat + 4 : idat + 12] = b"\x00" * 8  # the zlib header broken: CRC fixed so only the decoder sees it
    length = struct.unpack(">I", data[idat - 4 : idat])[0]
    data[idat + 4 + length : idat + 8 + length] = struct.pack(">I", zlib.crc32(bytes(data[idat : idat + 4 + length])))
    ei.check_stream(bytes(data), "png")
    with pytest.raises(ei.EncodedImageError, match="could not decode the PNG stream"):
        ei.decode(bytes(data), header, grey=False)
