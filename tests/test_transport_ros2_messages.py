"""CDR <-> numpy for Image, CameraInfo, PointCloud2, DisparityImage, TFMessage: a hand-decoded Image, bounds."""

from __future__ import annotations

import struct

import cv2
import numpy as np
import pytest

from helpers.hostile import png_bomb
from helpers.ros2_robot import TS, tf_message
from vpp_service.frame import Calibration
from vpp_service.transport.ros2 import messages as m
from vpp_service.transport.ros2.errors import Ros2Error
from vpp_service.transport.ros2.keys import (
    CAMERA_INFO,
    COMPRESSED_IMAGE,
    DISPARITY_IMAGE,
    IMAGE,
    POINT_CLOUD2,
    TF_MESSAGE,
    type_hash,
)

LIMITS = m.Limits()

# sensor_msgs/Image, 2 x 1 mono8, stamp 1 s 2 ns, frame "cam", pixels 7 and 9, written byte by byte:
# CDR little endian, alignment counted from after the 4-byte encapsulation header.
TINY_IMAGE = bytes.fromhex(
    "00010000"  # encapsulation: CDR_LE, options 0
    "01000000"  # header.stamp.sec = 1
    "02000000"  # header.stamp.nanosec = 2
    "04000000"
    "63616d00"  # header.frame_id = "cam" (length with NUL)
    "01000000"  # height = 1
    "02000000"  # width = 2
    "06000000"
    "6d6f6e6f3800"  # encoding = "mono8"
    "00"  # is_bigendian
    "00"  # padding to 4
    "02000000"  # step = 2
    "02000000"
    "0709"  # data: length 2, bytes 7 9
)


def image(arr: np.ndarray, encoding: str, step: int | None = None, big: bool = False) -> m.Image:
    data = np.ascontiguousarray(arr).view(np.uint8)
    h = arr.shape[0]
    row = data.reshape(h, -1)
    if step is not None:
        pad = np.zeros((h, step - row.shape[1]), np.uint8)
        row = np.hstack([row, pad])
    return m.Image(
        header=m.make_header(5, "f"),
        height=h,
        width=arr.shape[1],
        encoding=encoding,
        is_bigendian=int(big),
        step=row.shape[1],
        data=row.reshape(-1),
    )


def roundtrip(msg, ros_type, cls):
    return m.deserialize(m.serialize(msg, ros_type), ros_type, cls, LIMITS)


def test_hand_decoded_tiny_image():
    msg = m.deserialize(TINY_IMAGE, IMAGE, m.Image, LIMITS)
    assert (msg.height, msg.width, msg.encoding, msg.step) == (1, 2, "mono8", 2)
    assert m.stamp_ns(msg.header) == 1_000_000_002 and msg.header.frame_id == "cam"
    np.testing.assert_array_equal(m.image_to_array(msg, LIMITS), [[7, 9]])
    assert bytes(m.serialize(msg, IMAGE)) == TINY_IMAGE


def test_rgb_bgr_mono_and_padding():
    rng = np.random.default_rng(0)
    rgb = rng.integers(0, 256, (3, 4, 3), dtype=np.uint8)
    got = m.image_to_array(roundtrip(image(rgb, "rgb8", step=16), IMAGE, m.Image), LIMITS)
    np.testing.assert_array_equal(got, rgb)
    got = m.image_to_array(roundtrip(image(rgb[:, :, ::-1].copy(), "bgr8"), IMAGE, m.Image), LIMITS)
    np.testing.assert_array_equal(got, rgb)
    mono = rgb[:, :, 0].copy()
    np.testing.assert_array_equal(m.image_to_array(roundtrip(image(mono, "mono8"), IMAGE, m.Image), LIMITS), mono)


@pytest.mark.parametrize("big", [False, True])
def test_mono16_scaled(big):
    v = np.array([[0, 257, 65535, 32768]], dtype=">u2" if big else "<u2")
    got = m.image_to_array(image(v, "mono16", big=big), LIMITS)
    np.testing.assert_array_equal(got, [[0, 1, 255, 128]])


def test_unsupported_encoding_named():
    with pytest.raises(Ros2Error) as err:
        m.image_to_array(image(np.zeros((2, 2), np.uint8), "nv21"), LIMITS)
    assert err.value.reason == "encoding" and "nv21" in str(err.value) and "bayer_rggb8" in str(err.value)


def smooth_rgb(h: int = 40, w: int = 64, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return cv2.GaussianBlur(rng.integers(0, 256, (h, w, 3), dtype=np.uint8), (9, 9), 0)


def mosaic(rgb: np.ndarray, pattern: str) -> np.ndarray:
    """What a Bayer sensor of ``pattern`` (``"rggb"``: R at (0, 0), G at (0, 1), G at (1, 0), B at (1, 1)) records."""
    out = np.empty(rgb.shape[:2], np.uint8)
    for k, colour in enumerate(pattern):
        out[k // 2 :: 2, k % 2 :: 2] = rgb[k // 2 :: 2, k % 2 :: 2, "rgb".index(colour)]
    return out


@pytest.mark.parametrize("pattern", ["rggb", "bggr", "gbrg", "grbg"])
def test_bayer_demosaiced_with_the_ros_pattern(pattern):
    rgb = smooth_rgb()
    raw = mosaic(rgb, pattern)
    got = m.image_to_array(roundtrip(image(raw, f"bayer_{pattern}8"), IMAGE, m.Image), LIMITS)
    assert got.shape == rgb.shape
    inner = (slice(4, -4), slice(4, -4))
    err = np.abs(got[inner].astype(int) - rgb[inner].astype(int)).mean()
    assert err < 3.0, err
    swapped = {"rggb": "bggr", "bggr": "rggb", "gbrg": "grbg", "grbg": "gbrg"}[pattern]  # red and blue exchanged
    wrong = m.image_to_array(image(raw, f"bayer_{swapped}8"), LIMITS)
    assert np.abs(wrong[inner].astype(int) - rgb[inner].astype(int)).mean() > 3 * err


def yuv422(rgb: np.ndarray, order: str) -> np.ndarray:
    """Packed 4:2:2 (BT.601, video range) in byte ``order`` ``"uyvy"`` or ``"yuyv"``: H x 2W uint8."""
    f = rgb.astype(np.float64)
    r, g, b = f[..., 0], f[..., 1], f[..., 2]
    y = 16 + 0.257 * r + 0.504 * g + 0.098 * b
    u = 128 - 0.148 * r - 0.291 * g + 0.439 * b
    v = 128 + 0.439 * r - 0.368 * g - 0.071 * b
    u2, v2 = (u[:, 0::2] + u[:, 1::2]) / 2, (v[:, 0::2] + v[:, 1::2]) / 2  # one U and V per two pixels
    planes = {"y0": y[:, 0::2], "y1": y[:, 1::2], "u": u2, "v": v2}
    names = ["u", "y0", "v", "y1"] if order == "uyvy" else ["y0", "u", "y1", "v"]
    out = np.stack([planes[n] for n in names], axis=-1).reshape(rgb.shape[0], -1)
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)


@pytest.mark.parametrize(
    ("encoding", "order"), [("yuv422", "uyvy"), ("uyvy", "uyvy"), ("yuv422_yuy2", "yuyv"), ("yuyv", "yuyv")]
)
def test_yuv422_converted(encoding, order):
    rgb = smooth_rgb()
    packed = yuv422(rgb, order)
    msg = m.Image(
        header=m.make_header(5, "f"),
        height=rgb.shape[0],
        width=rgb.shape[1],
        encoding=encoding,
        is_bigendian=0,
        step=packed.shape[1],
        data=packed.reshape(-1),
    )
    got = m.image_to_array(roundtrip(msg, IMAGE, m.Image), LIMITS)
    assert got.shape == rgb.shape
    assert np.abs(got.astype(int) - rgb.astype(int)).mean() < 3.0
    msg.width, msg.step = rgb.shape[1] - 1, packed.shape[1] - 2
    msg.data = packed[:, :-2].reshape(-1).copy()
    with pytest.raises(Ros2Error, match="width 63 is odd") as err:
        m.image_to_array(msg, LIMITS)
    assert err.value.reason == "layout"


def test_rgba_and_bgra_lose_their_alpha():
    rgb = smooth_rgb(4, 6)
    alpha = np.full((4, 6, 1), 7, np.uint8)
    np.testing.assert_array_equal(m.image_to_array(image(np.concatenate([rgb, alpha], 2), "rgba8"), LIMITS), rgb)
    bgra = np.concatenate([rgb[:, :, ::-1], alpha], 2)
    np.testing.assert_array_equal(m.image_to_array(image(bgra, "bgra8", step=30), LIMITS), rgb)


def compressed(data: bytes, fmt: str) -> m.CompressedImage:
    msg = m.CompressedImage(header=m.make_header(5, "f"), format=fmt, data=np.frombuffer(data, np.uint8))
    return roundtrip(msg, COMPRESSED_IMAGE, m.CompressedImage)


def encoded(img: np.ndarray, ext: str, quality: int = 95) -> bytes:
    bgr = img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_RGB2BGR)  # as compressed_image_transport: bgr8
    ok, buf = cv2.imencode(ext, bgr, [cv2.IMWRITE_JPEG_QUALITY, quality] if ext == ".jpg" else [])
    assert ok
    return buf.tobytes()


@pytest.mark.parametrize(
    ("fmt", "ext", "grey"),
    [
        ("rgb8; jpeg compressed bgr8", ".jpg", False),
        ("bgr8; png compressed bgr8", ".png", False),
        ("mono8; jpeg compressed ", ".jpg", True),
        ("mono8; png compressed ", ".png", True),
        ("jpeg", ".jpg", False),  # older publishers: the codec alone
        ("png", ".png", True),
        ("", ".jpg", False),  # nothing named: the stream's magic bytes decide
    ],
)
def test_compressed_views_decoded(fmt, ext, grey):
    rgb = smooth_rgb()
    img = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY) if grey else rgb
    got = m.compressed_to_array(compressed(encoded(img, ext), fmt), LIMITS)
    assert got.shape == img.shape and got.dtype == np.uint8
    err = np.abs(got.astype(int) - img.astype(int))
    assert (err.max() == 0) if ext == ".png" else (err.mean() < 4.0)  # JPEG q95 (4:2:0 chroma) of a fine texture
    if not grey:  # RGB, not the stream's BGR
        assert np.abs(got.astype(int) - img[:, :, ::-1].astype(int)).mean() > 4 * max(err.mean(), 1.0)


def test_compressed_mono16_png_scaled_and_bayer_png_demosaiced():
    v = np.array([[0, 257, 65535, 32768]], np.uint16)
    _, buf = cv2.imencode(".png", v)
    got = m.compressed_to_array(compressed(buf.tobytes(), "mono16; png compressed "), LIMITS)
    np.testing.assert_array_equal(got, [[0, 1, 255, 128]])
    rgb = smooth_rgb()
    raw = mosaic(rgb, "grbg")
    got = m.compressed_to_array(compressed(encoded(raw, ".png"), "bayer_grbg8; png compressed "), LIMITS)
    want = m.image_to_array(image(raw, "bayer_grbg8"), LIMITS)
    np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize(
    ("fmt", "data", "reason", "message"),
    [
        ("rgb8; jpeg compressed bgr8", "truncated", "corrupt", "truncated JPEG stream (no end-of-image marker)"),
        ("rgb8; png compressed bgr8", "bomb", "too_large", "PNG stream declares 20000x20000 = 400000000 pixels"),
        ("rgb8; png compressed bgr8", "png_cut", "corrupt", "truncated PNG stream"),
        ("rgb8; jpeg compressed bgr8", "garbage", "corrupt", "not a PNG or JPEG stream"),
        ("rgb8; png compressed bgr8", "jpeg", "encoding", "says png, the data is a jpeg stream"),
        ("rgb8; tiff compressed bgr8", "jpeg", "encoding", "codec 'tiff' not supported; accepted: jpeg, png"),
        ("16UC1; compressedDepth png", "png", "encoding", "compressedDepth stream"),
    ],
)
def test_bad_compressed_views_refused_with_their_cause(fmt, data, reason, message):
    good_jpeg, good_png = encoded(smooth_rgb(), ".jpg"), encoded(smooth_rgb(), ".png")
    payload = {
        "truncated": good_jpeg[: len(good_jpeg) * 2 // 3],
        "bomb": png_bomb(20000, 20000),
        "png_cut": good_png[:-20],
        "garbage": b"\x00" * 64,
        "jpeg": good_jpeg,
        "png": good_png,
    }[data]
    with pytest.raises(Ros2Error) as err:
        m.compressed_to_array(compressed(payload, fmt), LIMITS)
    assert err.value.reason == reason and message in str(err.value), str(err.value)


def test_bounds_checked_before_work():
    big = image(np.zeros((4, 4), np.uint8), "mono8")
    with pytest.raises(Ros2Error) as err:
        m.image_to_array(big, m.Limits(max_pixels=15))
    assert err.value.reason == "too_large"
    payload = m.serialize(big, IMAGE)
    with pytest.raises(Ros2Error) as err:
        m.deserialize(payload, IMAGE, m.Image, m.Limits(max_bytes=len(payload) - 1))
    assert err.value.reason == "too_large"
    lying = image(np.zeros((4, 4), np.uint8), "mono8")
    lying.height = lying.width = 1 << 20  # claims a huge image, carries 16 bytes
    with pytest.raises(Ros2Error) as err:
        m.image_to_array(lying, LIMITS)
    assert err.value.reason == "too_large"
    lying.height, lying.width = 5, 4
    with pytest.raises(Ros2Error) as err:
        m.image_to_array(lying, LIMITS)
    assert err.value.reason == "layout"


@pytest.mark.parametrize("cut", [3, 10, len(TINY_IMAGE) - 1])
def test_truncated_cdr_rejected(cut):
    with pytest.raises(Ros2Error) as err:
        m.deserialize(TINY_IMAGE[:cut], IMAGE, m.Image, LIMITS)
    assert err.value.reason == "cdr"


def test_wrong_class_rejected():
    with pytest.raises(Ros2Error, match="decoded as"):
        m.deserialize(TINY_IMAGE, IMAGE, m.CameraInfo, LIMITS)


def test_depth_images():
    z = np.array([[1.5, 0.0, np.nan, -1.0]], np.float32)
    got = m.depth_image_to_array(image(z, "32FC1"), LIMITS)
    np.testing.assert_array_equal(got, [[1.5, np.nan, np.nan, np.nan]])
    mm = np.array([[1500, 0, 65535]], np.uint16)
    got = m.depth_image_to_array(image(mm, "16UC1"), LIMITS)
    np.testing.assert_allclose(got, [[1.5, np.nan, 65.535]])
    with pytest.raises(Ros2Error, match="depth encoding"):
        m.depth_image_to_array(image(mm.astype(np.uint8), "mono8"), LIMITS)


def test_calibration_from_camera_info():
    calib = Calibration(f=500.0, baseline=0.12, doffs=30.0, cx=300.0, cy=200.0)
    header = m.make_header(1, "left")
    left = m.camera_model(roundtrip(m.camera_info_message(calib, header, 640, 480, False), CAMERA_INFO, m.CameraInfo))
    right = m.camera_model(m.camera_info_message(calib, header, 640, 480, True))
    assert right.p[0, 3] == pytest.approx(-60.0) and right.p[0, 2] == 330.0
    got = m.stereo_calibration(left, right)
    assert (got.f, got.doffs, got.cx, got.cy) == (500.0, 30.0, 300.0, 200.0)
    assert got.baseline == pytest.approx(0.12, rel=1e-12)
    bad = m.camera_info_message(Calibration(f=400.0, baseline=0.12), header, 640, 480, True)
    with pytest.raises(Ros2Error, match="rectified pair"):
        m.stereo_calibration(left, m.camera_model(bad))
    flipped = m.camera_info_message(calib, header, 640, 480, True)
    flipped.p[3] = 60.0
    with pytest.raises(Ros2Error, match="baseline"):
        m.stereo_calibration(left, m.camera_model(flipped))
    nan_p = m.camera_info_message(calib, header, 640, 480, False)
    nan_p.p[0] = np.nan
    with pytest.raises(Ros2Error) as err:
        m.camera_model(nan_p)
    assert err.value.reason == "calibration"


def test_cloud_fields_and_layout():
    xyz = np.array([[1, 2, 3], [4, 5, 6]], np.float32)
    rgb = np.array([[255, 0, 1], [2, 3, 4]], np.uint8)
    msg = roundtrip(m.xyz_cloud_message(xyz, m.make_header(0, "lidar"), rgb), POINT_CLOUD2, m.PointCloud2)
    assert [f.name for f in msg.fields] == ["x", "y", "z", "rgb"] and msg.point_step == 16
    np.testing.assert_array_equal(m.cloud_to_xyz(msg, LIMITS), xyz)
    packed = msg.data.reshape(2, 16)[:, 12:16].copy().view("<u4").reshape(-1)
    assert packed[0] == 0xFF0001
    with pytest.raises(Ros2Error) as err:
        m.cloud_to_xyz(msg, m.Limits(max_points=1))
    assert err.value.reason == "too_large"
    msg.fields = msg.fields[1:]
    with pytest.raises(Ros2Error, match="no 'x' field"):
        m.cloud_to_xyz(msg, LIMITS)


def test_organized_cloud():
    xyz = np.array([[1, 2, 3], [np.nan] * 3, [4, 5, 6], [7, 8, 9], [1, 1, 1], [2, 2, 2]], np.float32)
    msg = roundtrip(m.xyz_cloud_message(xyz, m.make_header(0, "left"), shape=(2, 3)), POINT_CLOUD2, m.PointCloud2)
    assert (msg.height, msg.width, msg.row_step, msg.is_dense) == (2, 3, 36, False)
    np.testing.assert_array_equal(m.cloud_to_xyz(msg, LIMITS), xyz)
    dense = m.xyz_cloud_message(xyz[[0, 2, 3, 4]], m.make_header(0, "left"), shape=(2, 2))
    assert dense.is_dense and dense.height == 2
    with pytest.raises(ValueError, match="shape"):
        m.xyz_cloud_message(xyz, m.make_header(0, "left"), shape=(2, 2))


def test_cloud_big_endian_float64_and_padding():
    pts = np.zeros(3, dtype=[("pad", "u1", 4), ("x", ">f8"), ("y", ">f8"), ("z", ">f8"), ("i", ">f4")])
    pts["x"], pts["y"], pts["z"] = [1, 2, 3], [4, 5, 6], [7, 8, 9]
    f = [m.PointField(name=n, offset=o, datatype=8, count=1) for n, o in (("x", 4), ("y", 12), ("z", 20))] + [
        m.PointField(name="i", offset=28, datatype=7, count=1)
    ]
    msg = m.PointCloud2(
        header=m.make_header(0, "l"),
        height=1,
        width=3,
        fields=f,
        is_bigendian=True,
        point_step=32,
        row_step=96,
        data=pts.view(np.uint8).reshape(-1),
        is_dense=True,
    )
    np.testing.assert_array_equal(m.cloud_to_xyz(msg, LIMITS), [[1, 4, 7], [2, 5, 8], [3, 6, 9]])
    msg.row_step = 95
    with pytest.raises(Ros2Error) as err:
        m.cloud_to_xyz(msg, LIMITS)
    assert err.value.reason == "layout"


def test_disparity_message_conventions():
    calib = Calibration(f=500.0, baseline=0.1, doffs=20.0)
    d = np.array([[np.nan, 10.0, 12.5], [np.nan, np.nan, 11.0]], np.float32)
    msg = m.disparity_message(d, calib, m.make_header(42, "left_optical"), m.DisparityRange(max_disparity=64.0))
    msg = roundtrip(msg, DISPARITY_IMAGE, m.DisparityImage)
    assert msg.image.encoding == "32FC1" and msg.image.step == 12
    assert msg.f == 500.0 and msg.t == pytest.approx(0.1) and msg.delta_d == 1 / 16
    assert msg.min_disparity == 20.0 and msg.max_disparity == 84.0
    assert m.stamp_ns(msg.header) == 42 and msg.header.frame_id == "left_optical"
    w = msg.valid_window
    assert (w.x_offset, w.y_offset, w.width, w.height) == (1, 0, 2, 2)
    raw = msg.image.data.view("<f4").reshape(2, 3)
    assert raw[0, 0] == 19.0 and raw[0, 1] == 30.0  # invalid below min_disparity; values + doffs
    back = m.disparity_from_message(msg, LIMITS)
    np.testing.assert_array_equal(back.image, d + 20.0)
    nan_msg = m.disparity_message(d, calib, msg.header, m.DisparityRange(invalid="nan"))
    assert np.isnan(nan_msg.image.data.view("<f4")[0]) and nan_msg.max_disparity == 32.5
    depth = calib.f * back.t / back.image
    np.testing.assert_allclose(depth[0, 1], 500 * 0.1 / 30.0, rtol=1e-6)


def test_array_to_image_checks():
    with pytest.raises(ValueError, match="rgb8"):
        m.array_to_image(np.zeros((2, 2), np.uint8), m.make_header(0, ""), "rgb8")
    msg = m.array_to_image(np.zeros((2, 3), np.float32), m.make_header(0, ""), "32FC1")
    assert msg.step == 12 and msg.data.size == 24
    assert struct.unpack("<I", bytes(m.serialize(msg, IMAGE))[-28:-24])[0] == 24


def test_tf_message_type_hash():
    # REP 2011 hash of tf2_msgs/msg/TFMessage, computed with rosbags' Jazzy type store (an independent implementation)
    golden = "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"
    assert type_hash(TF_MESSAGE) == TS.hash_rihs01(TF_MESSAGE) == golden


def test_tf_transforms():
    s = 0.5**0.5
    # 90 degrees about z: (x, y, z, w) = (0, 0, sin 45, cos 45) -> R = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]
    msg = tf_message([("/base_link", "velodyne", (1.0, 2.0, 3.0), (0.0, 0.0, s, s))])
    payload = bytes(TS.serialize_cdr(msg, TF_MESSAGE, little_endian=True))
    (t,) = m.tf_transforms(m.deserialize(payload, TF_MESSAGE, m.TFMessage, LIMITS))
    assert (t.parent, t.child) == ("base_link", "velodyne")  # leading / dropped, as tf2 does
    want = np.array([[0, -1, 0, 1], [1, 0, 0, 2], [0, 0, 1, 3], [0, 0, 0, 1]], np.float64)
    np.testing.assert_allclose(t.matrix, want, atol=1e-12)


@pytest.mark.parametrize(
    "entry",
    [
        ("base", "base", (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)),  # its own parent
        ("", "lidar", (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)),  # no parent
        ("base", "lidar", (0.0, float("nan"), 0.0), (0.0, 0.0, 0.0, 1.0)),
        ("base", "lidar", (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 0.0)),  # not a rotation
        ("base", "lidar", (0.0, 0.0, 0.0), (0.0, 0.0, 0.1, 1.0)),  # |q|^2 = 1.01
    ],
)
def test_bad_transforms_refused(entry):
    with pytest.raises(Ros2Error) as err:
        m.tf_transforms(tf_message([entry]))
    assert err.value.reason == "tf"
