"""ROS 2 messages <-> numpy: ``Image``, ``CompressedImage``, ``CameraInfo``, ``PointCloud2``, ``DisparityImage``, ...

The CDR codec is the ``rosbags`` type store (Jazzy definitions; these types are
identical from Iron through Rolling). Decoding an ``Image`` is zero-copy where the
layout allows (``rgb8``/``mono8`` without row padding): the array is a read-only view
of the payload.

Every decoder bounds the cost before doing work: the payload size is checked before
the CDR is parsed (:class:`Limits`), then the pixel or point count before any array
is built; a ``CompressedImage``'s size is read from its PNG/JPEG header and bounded
before the stream is decoded (:mod:`vpp_service.transport.encoded_image`). A refused
message raises :class:`~vpp_service.transport.ros2.errors.Ros2Error` whose ``reason``
names the cause (``too_large``, ``cdr``, ``encoding``, ``layout``, ``corrupt``,
``calibration``, ``fields``, ``tf``).

Conventions of the ``DisparityImage`` we write (as stereo_image_proc fills it):
``image`` is ``32FC1`` with step ``4 * width``; values are ``x_l - x_r - (cx_l - cx_r)``
(i.e. the project's disparity plus ``doffs``); ``f`` = ``P_right[0]``, ``t`` = the
baseline in metres; ``min_disparity``/``max_disparity`` are in the image's own
(corrected) units; invalid pixels hold ``min_disparity - 1`` (below ``min_disparity``,
as the message definition says) or NaN (``invalid = "nan"``).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Annotated, Literal, TypeVar

import cv2
import numpy as np

from vpp_service.frame import Calibration
from vpp_service.settings import Options, Range
from vpp_service.transport import encoded_image
from vpp_service.transport.ros2.errors import Ros2Error
from vpp_service.transport.ros2.keys import (
    CAMERA_INFO,
    COMPRESSED_IMAGE,
    DISPARITY_IMAGE,
    IMAGE,
    POINT_CLOUD2,
    TF_MESSAGE,
)
from vpp_service.transport.wire import DEFAULT_LIMITS

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore
    from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__CameraInfo as CameraInfo
    from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__CompressedImage as CompressedImage
    from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__Image as Image
    from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__PointCloud2 as PointCloud2
    from rosbags.typesys.stores.ros2_jazzy import std_msgs__msg__Header as Header
    from rosbags.typesys.stores.ros2_jazzy import stereo_msgs__msg__DisparityImage as DisparityImage
    from rosbags.typesys.stores.ros2_jazzy import tf2_msgs__msg__TFMessage as TFMessage

M = TypeVar("M")

#: Bayer mosaics (8 bit) -> OpenCV's demosaicing to RGB, edge-aware. OpenCV names a pattern by the second row's
#: second and third pixels, so ROS's ``rggb`` (R at (0, 0)) is OpenCV's ``BG`` (cv_bridge's mapping).
_BAYER = {
    "bayer_rggb8": cv2.COLOR_BayerBG2RGB_EA,
    "bayer_bggr8": cv2.COLOR_BayerRG2RGB_EA,
    "bayer_gbrg8": cv2.COLOR_BayerGR2RGB_EA,
    "bayer_grbg8": cv2.COLOR_BayerGB2RGB_EA,
}
#: Packed YUV 4:2:2 (2 bytes a pixel) -> OpenCV's conversion to RGB. ``yuv422`` is UYVY (cv_bridge's reading);
#: ``uyvy``, ``yuyv`` and ``yuv422_yuy2`` are the names sensor_msgs added later.
_YUV422 = {
    "yuv422": cv2.COLOR_YUV2RGB_UYVY,
    "uyvy": cv2.COLOR_YUV2RGB_UYVY,
    "yuv422_yuy2": cv2.COLOR_YUV2RGB_YUY2,
    "yuyv": cv2.COLOR_YUV2RGB_YUY2,
}
#: Bytes per pixel of each image encoding accepted as stereo input.
_STEREO_BPP = {
    "rgb8": 3,
    "bgr8": 3,
    "rgba8": 4,
    "bgra8": 4,
    "mono8": 1,
    "mono16": 2,
    **dict.fromkeys(_BAYER, 1),
    **dict.fromkeys(_YUV422, 2),
}
#: Image encodings accepted as stereo input.
STEREO_ENCODINGS = tuple(_STEREO_BPP)
#: Codecs of a ``CompressedImage`` accepted as stereo input (the ``compressed`` transport's two).
COMPRESSED_CODECS = ("jpeg", "png")
#: Image encodings accepted as a depth map registered to the left camera.
DEPTH_ENCODINGS = ("32FC1", "16UC1")
#: How invalid disparity pixels are written.
Invalid = Literal["below_min", "nan"]

#: The message classes, importable from this module (``messages.Image``); ``rosbags`` loads on first use.
_CLASSES = {
    "Time": "builtin_interfaces__msg__Time",
    "Header": "std_msgs__msg__Header",
    "Image": "sensor_msgs__msg__Image",
    "CompressedImage": "sensor_msgs__msg__CompressedImage",
    "CameraInfo": "sensor_msgs__msg__CameraInfo",
    "RegionOfInterest": "sensor_msgs__msg__RegionOfInterest",
    "PointField": "sensor_msgs__msg__PointField",
    "PointCloud2": "sensor_msgs__msg__PointCloud2",
    "DisparityImage": "stereo_msgs__msg__DisparityImage",
    "TFMessage": "tf2_msgs__msg__TFMessage",
}
_SUPPORTED = {
    IMAGE: "Image",
    COMPRESSED_IMAGE: "CompressedImage",
    CAMERA_INFO: "CameraInfo",
    POINT_CLOUD2: "PointCloud2",
    DISPARITY_IMAGE: "DisparityImage",
    TF_MESSAGE: "TFMessage",
}


def __getattr__(name: str) -> type:
    """The ``rosbags`` message classes by short name, imported on first use (it takes ~0.3 s)."""
    if name in _CLASSES:
        from rosbags.typesys.stores import ros2_jazzy

        cls: type = getattr(ros2_jazzy, _CLASSES[name])
        return cls
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


@dataclass(frozen=True)
class Limits(Options):
    """Bounds checked before a message costs anything.

    Attributes
    ----------
    max_bytes : int
        Largest serialized message accepted (checked before CDR parsing); the
        msgpack wire format's cap by default.
    max_pixels : int
        Largest ``width * height`` of an image; the wire format's cap by default.
    max_points : int
        Largest ``width * height`` of a point cloud (4 Mi: 16-byte x/y/z points
        then fill the byte cap).
    """

    max_bytes: Annotated[int, Range(1)] = DEFAULT_LIMITS.max_message_bytes
    max_pixels: Annotated[int, Range(1)] = DEFAULT_LIMITS.max_pixels
    max_points: Annotated[int, Range(1)] = 4 * 1024 * 1024


def message_class(ros_type: str) -> type:
    """The ``rosbags`` class of one of the supported types (``sensor_msgs/msg/Image`` -> ``Image``)."""
    if ros_type not in _SUPPORTED:
        raise ValueError(f"unsupported message type {ros_type!r}; supported: {', '.join(_SUPPORTED)}")
    return __getattr__(_SUPPORTED[ros_type])


@functools.cache
def typestore() -> Typestore:
    """The ``rosbags`` type store used for every message (built once, on first use)."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


# ----------------------------------------------------------------------------- CDR


def deserialize(data: bytes | memoryview, ros_type: str, cls: type[M], limits: Limits) -> M:
    """Parse a CDR payload of ``ros_type`` after checking its size.

    Parameters
    ----------
    data : bytes or memoryview
        Payload: 4-byte encapsulation header then the body.
    ros_type : str
        ``pkg/msg/Msg`` (one of the supported types).
    cls : type
        The expected message class (the result is checked against it).
    limits : Limits
        ``max_bytes`` is checked first.

    Raises
    ------
    Ros2Error
        ``too_large`` or ``cdr`` (truncated, bad encapsulation, wrong type).
    """
    if len(data) > limits.max_bytes:
        raise Ros2Error("too_large", f"{ros_type}: {len(data)} bytes > max {limits.max_bytes}")
    if len(data) < 4 or bytes(data[:4]) not in (b"\x00\x01\x00\x00", b"\x00\x00\x00\x00"):
        raise Ros2Error("cdr", f"{ros_type}: not a CDR payload (encapsulation {bytes(data[:4]).hex()})")
    try:
        msg = typestore().deserialize_cdr(data, ros_type)
    except Exception as exc:  # noqa: BLE001 - rosbags raises assorted errors on malformed CDR; all mean "bad payload"
        raise Ros2Error("cdr", f"{ros_type}: {type(exc).__name__}: {exc}") from None
    if not isinstance(msg, cls):
        raise Ros2Error("cdr", f"{ros_type}: decoded as {type(msg).__name__}")
    return msg


def serialize(msg: object, ros_type: str) -> bytes | bytearray:
    """CDR (little endian, header ``00 01 00 00``) of ``msg``, without a copy of the buffer rosbags wrote."""
    if ros_type not in _SUPPORTED or getattr(type(msg), "__msgtype__", None) != ros_type:
        raise TypeError(f"{ros_type}: got a {type(msg).__name__}")
    view = typestore().serialize_cdr(msg, ros_type, little_endian=True)
    buf = view.obj
    return buf if isinstance(buf, bytearray) and len(buf) == view.nbytes else bytes(view)


# -------------------------------------------------------------------------- header


def stamp_ns(header: Header) -> int:
    """The header stamp in ns."""
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def make_header(stamp: int, frame_id: str) -> Header:
    """A header with ``stamp`` (ns, >= 0) and ``frame_id``."""
    if stamp < 0:
        raise ValueError(f"stamp must be >= 0 ns, got {stamp}")
    from rosbags.typesys.stores.ros2_jazzy import builtin_interfaces__msg__Time as Time
    from rosbags.typesys.stores.ros2_jazzy import std_msgs__msg__Header as Header

    sec, nsec = divmod(int(stamp), 1_000_000_000)
    return Header(stamp=Time(sec=sec, nanosec=nsec), frame_id=frame_id)


# -------------------------------------------------------------------------- images


def _pixels(msg: Image, bpp: int, limits: Limits) -> np.ndarray:
    """The image bytes as an H x (W * bpp) uint8 view, after the size and layout checks."""
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    if h < 1 or w < 1:
        raise Ros2Error("layout", f"image {w}x{h}: empty")
    if h * w > limits.max_pixels:
        raise Ros2Error("too_large", f"image {w}x{h}: {h * w} pixels > max {limits.max_pixels}")
    if step < w * bpp:
        raise Ros2Error("layout", f"image step {step} < width {w} x {bpp} bytes")
    if msg.data.size != step * h:
        raise Ros2Error("layout", f"image data {msg.data.size} bytes != step {step} x height {h}")
    return msg.data.reshape(h, step)[:, : w * bpp]


def _mono16_to_8(v: np.ndarray) -> np.ndarray:
    """16-bit samples to 8 bits by ``v / 257``, rounded: the full 16-bit range onto the full 8-bit range."""
    return ((v.astype(np.uint32) * 255 + 32767) // 65535).astype(np.uint8)


def image_to_array(msg: Image, limits: Limits) -> np.ndarray:
    """A stereo input image as H x W (mono) or H x W x 3 (RGB) uint8.

    - ``rgb8`` and ``mono8`` without row padding are read-only views of the payload;
      ``bgr8`` is reordered to RGB; ``rgba8``/``bgra8`` lose their alpha.
    - ``mono16`` is scaled to 8 bits by ``v / 257`` (the full 16-bit range onto the full
      8-bit range, rounded; big-endian data is honoured). A 10- or 12-bit camera that
      publishes its counts unscaled in ``mono16`` thus uses only the lowest levels.
    - ``bayer_rggb8``, ``bayer_bggr8``, ``bayer_gbrg8``, ``bayer_grbg8`` are demosaiced to
      RGB (OpenCV's edge-aware demosaicing).
    - ``yuv422`` (= ``uyvy``, byte order U Y V Y) and ``yuv422_yuy2`` (= ``yuyv``, Y U Y V)
      are converted to RGB (BT.601); their width must be even.

    Raises
    ------
    Ros2Error
        ``encoding`` (not in :data:`STEREO_ENCODINGS`), ``too_large`` or ``layout``.
    """
    enc = msg.encoding
    if enc not in _STEREO_BPP:
        raise Ros2Error("encoding", f"image encoding {enc!r} not supported; accepted: {', '.join(STEREO_ENCODINGS)}")
    bpp = _STEREO_BPP[enc]
    px = _pixels(msg, bpp, limits)
    h, w = int(msg.height), int(msg.width)
    if enc == "mono8":
        return px
    if enc == "mono16":
        return _mono16_to_8(np.ascontiguousarray(px).view(">u2" if msg.is_bigendian else "<u2").reshape(h, w))
    if enc in _BAYER:
        return cv2.cvtColor(np.ascontiguousarray(px), _BAYER[enc])
    if enc in _YUV422:
        if w % 2:
            raise Ros2Error("layout", f"{enc} image width {w} is odd (two pixels share their U and V)")
        return cv2.cvtColor(np.ascontiguousarray(px).reshape(h, w, 2), _YUV422[enc])
    pixels = px.reshape(h, w, bpp)
    if enc == "rgb8":
        return pixels
    return np.ascontiguousarray(pixels[:, :, 2::-1] if enc.startswith("bgr") else pixels[:, :, :3])


def _compressed_format(fmt: str) -> tuple[str, str | None]:
    """``(original encoding, codec)`` of a ``CompressedImage.format`` as image_transport writes it.

    ``"rgb8; jpeg compressed bgr8"``, ``"mono8; png compressed "`` (compressed_image_transport) or
    just ``"jpeg"`` / ``"png"`` (older publishers); an empty format names nothing (the stream's magic
    bytes decide). The codec is None when the format names none.

    Raises
    ------
    Ros2Error
        ``encoding``: a codec other than JPEG or PNG, or a ``compressedDepth`` stream.
    """
    original, sep, rest = fmt.partition(";")
    if not sep:
        original, rest = "", original
    words = rest.strip().lower().split()
    if "compresseddepth" in words:
        raise Ros2Error("encoding", f"compressed format {fmt!r} is a compressedDepth stream (a depth map, not a view)")
    if not words:
        return original.strip(), None
    codec = {"jpeg": "jpeg", "jpg": "jpeg", "png": "png"}.get(words[0])
    if codec is None:
        raise Ros2Error("encoding", f"compressed format {fmt!r}: codec {words[0]!r} not supported; accepted: jpeg, png")
    return original.strip(), codec


def compressed_to_array(msg: CompressedImage, limits: Limits) -> np.ndarray:
    """A ``CompressedImage`` stereo view (JPEG or PNG) as H x W (mono) or H x W x 3 (RGB) uint8.

    The stream's header is read first and its declared size bounded by ``max_pixels``
    before anything is decoded (a PNG or JPEG "bomb" is refused, ``too_large``); then the
    stream's structure is checked (a PNG's chunks and CRCs, a JPEG's end-of-image marker:
    a truncated stream is refused, ``corrupt``); only then is it decoded. A one-component
    stream (``mono8``/``mono16`` as compressed_image_transport writes them) gives a mono
    image, others RGB (alpha dropped); 16-bit PNG samples are scaled as ``mono16`` is; a
    one-component stream whose format names a ``bayer_*`` encoding is demosaiced.

    Raises
    ------
    Ros2Error
        ``encoding`` (the format names another codec than the stream's, or one other than
        JPEG/PNG), ``too_large`` (declared size over ``max_pixels``) or ``corrupt`` (not a
        PNG/JPEG stream, truncated, bad CRC, undecodable).
    """
    original, named = _compressed_format(str(msg.format))
    data = msg.data
    try:
        header = encoded_image.probe(data, limits.max_pixels)
        if named is not None and named != header.codec:
            raise Ros2Error(
                "encoding", f"compressed format {msg.format!r} says {named}, the data is a {header.codec} stream"
            )
        encoded_image.check_stream(data, header.codec)
        bayer = _BAYER.get(original.lower()[: len("bayer_rggb")] + "8") if header.channels == 1 else None
        img = encoded_image.decode(data, header, grey=header.channels <= 2 or original.startswith("mono"))
    except encoded_image.TooLargeError as exc:
        raise Ros2Error("too_large", f"compressed image: {exc}") from None
    except encoded_image.EncodedImageError as exc:
        raise Ros2Error("corrupt", f"compressed image: {exc}") from None
    return cv2.cvtColor(img, bayer) if bayer is not None else img


def depth_image_to_array(msg: Image, limits: Limits) -> np.ndarray:
    """A depth image registered to the left camera as H x W float32 metres, NaN = no measurement.

    ``32FC1`` is metres, ``16UC1`` millimetres; 0, NaN, infinities and negative values
    mean no measurement.

    Raises
    ------
    Ros2Error
        ``encoding`` (not in :data:`DEPTH_ENCODINGS`), ``too_large`` or ``layout``.
    """
    enc = msg.encoding
    if enc not in DEPTH_ENCODINGS:
        raise Ros2Error("encoding", f"depth encoding {enc!r} not supported; accepted: {', '.join(DEPTH_ENCODINGS)}")
    h, w = int(msg.height), int(msg.width)
    bpp = 4 if enc == "32FC1" else 2
    px = np.ascontiguousarray(_pixels(msg, bpp, limits))
    order = ">" if msg.is_bigendian else "<"
    if enc == "32FC1":
        z = px.view(f"{order}f4").reshape(h, w).astype(np.float32)
    else:
        z = px.view(f"{order}u2").reshape(h, w).astype(np.float32) * np.float32(1e-3)
    z[~(np.isfinite(z) & (z > 0))] = np.nan
    return z


def array_to_image(arr: np.ndarray, header: Header, encoding: Literal["rgb8", "mono8", "32FC1"]) -> Image:
    """An ``Image`` message holding ``arr`` (H x W x 3 uint8 ``rgb8``, H x W uint8 ``mono8``, float32 ``32FC1``)."""
    from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__Image as Image

    want = {"rgb8": (np.uint8, 3), "mono8": (np.uint8, 2), "32FC1": (np.float32, 2)}
    if encoding not in want:
        raise ValueError(f"encoding must be one of {list(want)}, got {encoding!r}")
    dtype, ndim = want[encoding]
    if arr.dtype != dtype or arr.ndim != ndim or (ndim == 3 and arr.shape[2] != 3):
        raise ValueError(f"{encoding}: needs a {'H x W x 3' if ndim == 3 else 'H x W'} {np.dtype(dtype)} array")
    a = np.ascontiguousarray(arr, dtype=np.dtype(dtype).newbyteorder("<"))
    h, w = a.shape[:2]
    return Image(
        header=header,
        height=h,
        width=w,
        encoding=encoding,
        is_bigendian=0,
        step=a.nbytes // h,
        data=a.reshape(-1).view(np.uint8),
    )


# --------------------------------------------------------------------- camera_info


@dataclass(frozen=True)
class CameraModel:
    """What the service uses from a ``CameraInfo``.

    Attributes
    ----------
    width, height : int
        Image size the calibration is for.
    p : ndarray
        3 x 4 float64 projection matrix ``P`` of the rectified camera.
    frame_id : str
        Optical frame of the camera.
    stamp_ns : int
        Header stamp.
    """

    width: int
    height: int
    p: np.ndarray
    frame_id: str
    stamp_ns: int


def camera_model(msg: CameraInfo) -> CameraModel:
    """Check and extract ``P``, the size and the header of a ``CameraInfo``.

    Raises
    ------
    Ros2Error
        ``calibration``: ``P`` not 12 finite numbers, ``fx``/``fy`` <= 0, or an empty size.
    """
    p = np.asarray(msg.p, dtype=np.float64)
    if p.size != 12 or not np.all(np.isfinite(p)):
        raise Ros2Error("calibration", "camera_info P must hold 12 finite numbers")
    p = p.reshape(3, 4)
    if not p.any():
        raise Ros2Error("calibration", "camera_info P is all zeros (an uncalibrated camera)")
    if not (p[0, 0] > 0 and p[1, 1] > 0) or p[2, 2] != 1:
        raise Ros2Error("calibration", f"camera_info P has fx={p[0, 0]}, fy={p[1, 1]}, P[2,2]={p[2, 2]}")
    if int(msg.width) < 1 or int(msg.height) < 1:
        raise Ros2Error("calibration", f"camera_info size {msg.width}x{msg.height}")
    return CameraModel(int(msg.width), int(msg.height), p, msg.header.frame_id, stamp_ns(msg.header))


def stereo_calibration(left: CameraModel, right: CameraModel) -> Calibration:
    """The project's calibration from a rectified pair's camera_info.

    ``f = P_right[0]``, ``baseline = -P_right[3] / P_right[0]``, ``doffs = cx_r - cx_l``
    (so ``d_project + doffs = x_l - x_r - (cx_l - cx_r)``, the ROS disparity), ``cx``/``cy``
    of the left camera.

    Raises
    ------
    Ros2Error
        ``calibration``: the two focal lengths or sizes differ, or the baseline is not > 0.
    """
    f = float(right.p[0, 0])
    if abs(float(left.p[0, 0]) - f) > 1e-6 * f or (left.width, left.height) != (right.width, right.height):
        raise Ros2Error("calibration", "left and right camera_info are not a rectified pair (fx or size differ)")
    baseline = -float(right.p[0, 3]) / f
    if not (math.isfinite(baseline) and baseline > 0):
        raise Ros2Error("calibration", f"baseline -P_right[3]/P_right[0] = {baseline} m, must be > 0")
    cx_l, cx_r = float(left.p[0, 2]), float(right.p[0, 2])
    return Calibration(f=f, baseline=baseline, doffs=cx_r - cx_l, cx=cx_l, cy=float(left.p[1, 2]))


def camera_info_message(calib: Calibration, header: Header, width: int, height: int, right: bool) -> CameraInfo:
    """A rectified ``CameraInfo`` for one view of ``calib`` (``doffs`` moves the right ``cx``)."""
    from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__CameraInfo as CameraInfo
    from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__RegionOfInterest as RegionOfInterest

    cx_l = calib.cx if calib.cx is not None else (width - 1) / 2
    cy = calib.cy if calib.cy is not None else (height - 1) / 2
    cx = cx_l + calib.doffs if right else cx_l
    tx = -calib.f * calib.baseline if right else 0.0
    k = np.array([calib.f, 0, cx, 0, calib.f, cy, 0, 0, 1], np.float64)
    p = np.array([calib.f, 0, cx, tx, 0, calib.f, cy, 0, 0, 0, 1, 0], np.float64)
    return CameraInfo(
        header=header,
        height=height,
        width=width,
        distortion_model="plumb_bob",
        d=np.zeros(5, np.float64),
        k=k,
        r=np.eye(3).reshape(-1),
        p=p,
        binning_x=0,
        binning_y=0,
        roi=RegionOfInterest(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False),
    )


# --------------------------------------------------------------------- point cloud

#: ``PointField`` datatypes (INT8 = 1 ... FLOAT64 = 8) as numpy kinds.
_POINT_TYPES = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}
_FLOAT32 = 7


def cloud_to_xyz(msg: PointCloud2, limits: Limits) -> np.ndarray:
    """The ``x``, ``y``, ``z`` fields of a cloud as N x 3 float64 (other fields ignored).

    Raises
    ------
    Ros2Error
        ``fields`` (x/y/z missing, not scalar floats, or outside the point), ``too_large``
        (more than ``max_points``) or ``layout`` (steps and data size disagree).
    """
    h, w, ps, rs = int(msg.height), int(msg.width), int(msg.point_step), int(msg.row_step)
    n = h * w
    if n > limits.max_points:
        raise Ros2Error("too_large", f"cloud {w}x{h}: {n} points > max {limits.max_points}")
    if n == 0:
        return np.zeros((0, 3), np.float64)
    if ps < 1 or rs < w * ps or msg.data.size != rs * h:
        raise Ros2Error("layout", f"cloud point_step {ps}, row_step {rs}, data {msg.data.size} for {w}x{h}")
    fields = {f.name: f for f in msg.fields}
    order = ">" if msg.is_bigendian else "<"
    kinds: list[str] = []
    for name in ("x", "y", "z"):
        f = fields.get(name)
        if f is None:
            raise Ros2Error("fields", f"cloud has no {name!r} field (fields: {', '.join(fields) or 'none'})")
        kind = _POINT_TYPES.get(int(f.datatype))
        if kind not in ("f4", "f8") or int(f.count) != 1:
            raise Ros2Error("fields", f"cloud field {name!r}: datatype {f.datatype} x {f.count}, need one float")
        if not 0 <= int(f.offset) <= ps - int(kind[1]):
            raise Ros2Error("fields", f"cloud field {name!r}: offset {f.offset} outside point_step {ps}")
        kinds.append(f"{order}{kind}")
    # a structured view of the rows (no copy) picks the three fields out of each point
    view = np.dtype(
        {"names": ["x", "y", "z"], "formats": kinds, "offsets": [int(fields[n].offset) for n in "xyz"], "itemsize": ps}
    )
    rows = msg.data.reshape(h, rs)[:, : w * ps]
    pts = np.ascontiguousarray(rows).reshape(-1).view(view)
    out = np.empty((n, 3), np.float64)
    for i, name in enumerate(("x", "y", "z")):
        out[:, i] = pts[name]
    return out


def xyz_cloud_message(
    xyz: np.ndarray, header: Header, rgb: np.ndarray | None = None, shape: tuple[int, int] | None = None
) -> PointCloud2:
    """A cloud of N x 3 points, float32 x y z, plus packed ``rgb`` (N x 3 uint8) when given.

    ``shape`` = ``(H, W)`` with N = H x W makes it organized as stereo_image_proc's ``points2``
    (height H, width W, point ``v * W + u`` is pixel ``(v, u)``; invalid points are NaN);
    None (default) gives an unorganized cloud (height 1, width N). ``is_dense`` is true only
    when every coordinate is finite. Each point is 16 bytes, x y z rgb at offsets 0, 4, 8, 12
    (stereo_image_proc's layout with ``avoid_point_cloud_padding``); readers go by the fields.
    """
    from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__PointCloud2 as PointCloud2
    from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__PointField as PointField

    pts = np.ascontiguousarray(xyz, dtype="<f4").reshape(-1, 3)
    n = pts.shape[0]
    height, width = (1, n) if shape is None else (int(shape[0]), int(shape[1]))
    if height * width != n:
        raise ValueError(f"shape {shape} holds {height * width} points, got {n}")
    names = ["x", "y", "z"] + (["rgb"] if rgb is not None else [])
    rec = np.empty((n, len(names)), "<f4")
    rec[:, :3] = pts
    if rgb is not None:
        c = np.ascontiguousarray(rgb, dtype=np.uint8).reshape(n, 3).astype(np.uint32)
        rec[:, 3] = ((c[:, 0] << 16) | (c[:, 1] << 8) | c[:, 2]).astype("<u4").view("<f4")
    fields = [PointField(name=nm, offset=4 * i, datatype=_FLOAT32, count=1) for i, nm in enumerate(names)]
    step = 4 * len(names)
    return PointCloud2(
        header=header,
        height=height,
        width=width,
        fields=fields,
        is_bigendian=False,
        point_step=step,
        row_step=step * width,
        data=rec.reshape(-1).view(np.uint8),
        is_dense=bool(np.isfinite(pts).all()),
    )


# ----------------------------------------------------------------------------- tf

#: ``|q|^2`` farther than this from 1 makes a rotation invalid (tf2 ignores such a transform likewise).
_QUATERNION_TOLERANCE = 1e-5


@dataclass(frozen=True)
class Transform:
    """One transform of a ``TFMessage``: where ``child`` sits in ``parent``.

    Attributes
    ----------
    parent : str
        ``header.frame_id`` (leading ``/`` removed, as tf2 does).
    child : str
        ``child_frame_id`` (likewise).
    matrix : ndarray
        4 x 4 float64 taking a point in ``child`` to ``parent`` (rotation from the quaternion,
        translation in the last column).
    stamp_ns : int
        Header stamp.
    """

    parent: str
    child: str
    matrix: np.ndarray
    stamp_ns: int


def tf_transforms(msg: TFMessage) -> list[Transform]:
    """The transforms of a ``TFMessage`` as 4 x 4 matrices.

    Raises
    ------
    Ros2Error
        ``tf``: an empty frame id, a frame its own parent, a non-finite value, or a rotation
        that is not a unit quaternion (``|q|^2`` within 1e-5 of 1, tf2's check).
    """
    out: list[Transform] = []
    for t in msg.transforms:
        parent, child = t.header.frame_id.lstrip("/"), t.child_frame_id.lstrip("/")
        if not parent or not child or parent == child:
            raise Ros2Error("tf", f"transform {parent!r} -> {child!r}: needs two different frame ids")
        tr, q = t.transform.translation, t.transform.rotation
        x, y, z, w = float(q.x), float(q.y), float(q.z), float(q.w)
        offset = np.array([tr.x, tr.y, tr.z], np.float64)
        if not (np.all(np.isfinite(offset)) and all(math.isfinite(c) for c in (x, y, z, w))):
            raise Ros2Error("tf", f"transform {parent!r} -> {child!r}: non-finite value")
        if abs(x * x + y * y + z * z + w * w - 1.0) > _QUATERNION_TOLERANCE:
            raise Ros2Error(
                "tf", f"transform {parent!r} -> {child!r}: rotation {(x, y, z, w)} is not a unit quaternion"
            )
        m = np.eye(4)
        m[:3, :3] = [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
        m[:3, 3] = offset
        out.append(Transform(parent, child, m, stamp_ns(t.header)))
    return out


# ------------------------------------------------------------------- disparity


@dataclass(frozen=True)
class DisparityRange:
    """How the ``DisparityImage`` metadata is filled.

    Attributes
    ----------
    min_disparity : float
        The matcher's smallest disparity, in the project's (uncorrected) units.
    max_disparity : float
        The matcher's largest disparity (uncorrected); 0 = the frame's largest valid value.
    delta_d : float
        Smallest disparity step (``1/16`` for OpenCV's matchers).
    invalid : {"below_min", "nan"}
        Value of invalid pixels: ``min_disparity - 1`` (stereo_image_proc) or NaN.
    """

    min_disparity: float = 0.0
    max_disparity: float = 0.0
    delta_d: float = 1.0 / 16.0
    invalid: Invalid = "below_min"


def disparity_message(disparity: np.ndarray, calib: Calibration, header: Header, rng: DisparityRange) -> DisparityImage:
    """A ``stereo_msgs/DisparityImage`` from the project's H x W float32 disparity (NaN = invalid).

    Values become ``d + doffs`` (ROS units, see the module docstring); ``valid_window`` is the
    bounding box of the valid pixels (all zeros when there are none).
    """
    from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__RegionOfInterest as RegionOfInterest
    from rosbags.typesys.stores.ros2_jazzy import stereo_msgs__msg__DisparityImage as DisparityImage

    d = np.asarray(disparity, dtype=np.float32)
    if d.ndim != 2:
        raise ValueError(f"disparity must be H x W, got shape {d.shape}")
    out = d + np.float32(calib.doffs)
    # fmin/fmax skip NaN: one pass each, NaN when every pixel is invalid
    smallest, largest = float(np.fmin.reduce(out, axis=None)), float(np.fmax.reduce(d, axis=None))
    any_valid = math.isfinite(smallest)
    lo = rng.min_disparity + calib.doffs
    if any_valid:
        lo = min(lo, math.floor(smallest))
    hi_raw = rng.max_disparity if rng.max_disparity > 0 else (largest if any_valid else 0.0)
    hi = max(hi_raw + calib.doffs, lo)
    valid = np.isfinite(d)
    if rng.invalid == "below_min":
        np.copyto(out, np.float32(lo - 1.0), where=~valid)
    rows, cols = np.flatnonzero(valid.any(axis=1)), np.flatnonzero(valid.any(axis=0))
    if rows.size:
        window = RegionOfInterest(
            x_offset=int(cols[0]),
            y_offset=int(rows[0]),
            height=int(rows[-1] - rows[0] + 1),
            width=int(cols[-1] - cols[0] + 1),
            do_rectify=False,
        )
    else:
        window = RegionOfInterest(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
    return DisparityImage(
        header=header,
        image=array_to_image(out, header, "32FC1"),
        f=float(calib.f),
        t=float(calib.baseline),
        valid_window=window,
        min_disparity=float(lo),
        max_disparity=float(hi),
        delta_d=float(rng.delta_d),
    )


@dataclass(frozen=True)
class Disparity:
    """A decoded ``DisparityImage``: the map in ROS units (NaN where invalid) and its metadata."""

    image: np.ndarray
    f: float
    t: float
    min_disparity: float
    max_disparity: float
    header: Header


def disparity_from_message(msg: DisparityImage, limits: Limits) -> Disparity:
    """Decode a ``DisparityImage``; pixels below ``min_disparity`` (or NaN) become NaN.

    Raises
    ------
    Ros2Error
        ``encoding`` (not ``32FC1``), ``too_large`` or ``layout``.
    """
    img = msg.image
    if img.encoding != "32FC1":
        raise Ros2Error("encoding", f"disparity encoding {img.encoding!r}, expected '32FC1'")
    px = np.ascontiguousarray(_pixels(img, 4, limits))
    d = px.view(">f4" if img.is_bigendian else "<f4").reshape(int(img.height), int(img.width)).astype(np.float32)
    d[~(d >= np.float32(msg.min_disparity))] = np.nan
    return Disparity(d, float(msg.f), float(msg.t), float(msg.min_disparity), float(msg.max_disparity), msg.header)


__all__ = [
    "COMPRESSED_CODECS",
    "DEPTH_ENCODINGS",
    "STEREO_ENCODINGS",
    "CameraInfo",
    "CameraModel",
    "CompressedImage",
    "Disparity",
    "DisparityImage",
    "DisparityRange",
    "Header",
    "Image",
    "Invalid",
    "Limits",
    "PointCloud2",
    "TFMessage",
    "Transform",
    "array_to_image",
    "camera_info_message",
    "camera_model",
    "cloud_to_xyz",
    "compressed_to_array",
    "depth_image_to_array",
    "deserialize",
    "disparity_from_message",
    "disparity_message",
    "image_to_array",
    "make_header",
    "message_class",
    "serialize",
    "stamp_ns",
    "stereo_calibration",
    "tf_transforms",
    "typestore",
    "xyz_cloud_message",
]
