"""Wire format v1: msgpack messages between cameras, the service and its clients.

The format is documented (with a byte-level worked example) in
``docs/wire-format.md``; this module is its reference implementation.

Every decoder validates everything before touching the data: the message size,
msgpack container limits, the version, the type of every field, image sizes
against ``h * w * c``, encoded-image headers against the declared size (so a
hostile PNG/JPEG cannot make us allocate a huge buffer), finite calibration,
and sparse points inside the image. A violation raises :class:`WireError`
naming the field. Unknown keys are ignored (forward compatibility).

Topics (``prefix`` defaults to ``"vpp"``)::

    <prefix>/<rig>/in/frame          StereoFrame (left, right, calib, depth?)
    <prefix>/<rig>/in/left|right     Image topic message (separate-topics mode)
    <prefix>/<rig>/in/depth          depth topic message (separate-topics mode)
    <prefix>/<rig>/out/disparity     dense disparity, float32 px, NaN = invalid
    <prefix>/<rig>/out/depth         dense depth, float32 metres, NaN = invalid
    <prefix>/<rig>/out/confidence    per-pixel confidence of the disparity, float32 0..1 (0 = no answer)
    <prefix>/<rig>/out/left_vpp|right_vpp   painted pair, as Images
    <prefix>/<rig>/out/sparse        the sparse input points, n x 3 float32 (x, y, disparity)
    <prefix>/<rig>/out/points        the point cloud, n x 3 float32 x y z (metres) + n x 3 uint8 RGB
    <prefix>/<rig>/@status           queryable, JSON
    <prefix>/<rig>/@alive            liveliness token
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import cv2
import msgpack
import numpy as np

from vpp_service.frame import Calibration, FusionResult, StereoFrame
from vpp_service.transport import _points, encoded_image, msgview
from vpp_service.transport.backproject import DEFAULT_STRIDE, depth_to_points

#: Wire format version written and accepted.
VERSION = 1
#: Default key prefix.
DEFAULT_PREFIX = "vpp"
#: Output names a sink may publish.
OUTPUTS = ("disparity", "depth", "left_vpp", "right_vpp", "sparse", "points", "confidence")


class WireError(ValueError):
    """A message does not follow the wire format (the message names the field)."""


@dataclass(frozen=True)
class WireLimits:
    """Hard limits applied while decoding untrusted messages.

    Attributes
    ----------
    max_message_bytes : int
        Largest accepted message (checked before unpacking). The default,
        64 MiB, holds a raw full-resolution Middlebury pair (2964 x 1988 RGB,
        35 MB) with its sparse depth and float32 ground truth.
    max_side : int
        Largest accepted image height or width.
    max_pixels : int
        Largest accepted ``h * w`` of an image or depth map, checked before
        anything of that size is allocated or decoded. The default, 8 Mi
        pixels, admits full-resolution Middlebury (2964 x 1988 = 5.9 M) with
        room to spare; a hostile header cannot make a decoder allocate more.
    max_points : int
        Largest accepted number of sparse depth points.
    max_elements : int
        Largest number of msgpack objects in one message, however nested (a
        frame has fewer than 100): bounds the parsing work of any message.
    """

    max_message_bytes: int = 64 * 1024 * 1024
    max_side: int = 16384
    max_pixels: int = 8 * 1024 * 1024
    max_points: int = 16 * 1024 * 1024
    max_elements: int = 4096


DEFAULT_LIMITS = WireLimits()

#: A msgpack ``bin`` payload as the decoder hands it over (usually a read-only ``memoryview``).
Binary = bytes | bytearray | memoryview


# --------------------------------------------------------------------- keys
def topic(prefix: str, rig: str, name: str) -> str:
    """Key expression ``<prefix>/<rig>/<name>`` after validating the parts.

    Raises
    ------
    ValueError
        If ``prefix`` or ``rig`` is empty or contains wildcards / ``$`` / ``#`` / ``?``,
        or ``rig`` contains ``/``.
    """
    for arg, value in (("prefix", prefix), ("rig", rig)):
        if not isinstance(value, str) or not value:
            raise ValueError(f"{arg} must be a non-empty string, got {value!r}")
        if any(ch in value for ch in "*$#?") or value.startswith("/") or value.endswith("/"):
            raise ValueError(f"{arg} must be a plain key expression (no *, $, #, ?, leading/trailing /), got {value!r}")
    if "/" in rig:
        raise ValueError(f"rig must not contain '/', got {rig!r}")
    return f"{prefix}/{rig}/{name}"


# ------------------------------------------------------------ small helpers
def _req(msg: Mapping[str, object], key: str, path: str) -> object:
    if key not in msg:
        raise WireError(f"{path}{key}: missing")
    return msg[key]


def _int(msg: Mapping[str, object], key: str, path: str, lo: int, hi: int) -> int:
    v = _req(msg, key, path)
    if isinstance(v, bool) or not isinstance(v, int):
        raise WireError(f"{path}{key}: must be an integer, got {type(v).__name__}")
    if not lo <= v <= hi:
        raise WireError(f"{path}{key}: must be in [{lo}, {hi}], got {v}")
    return v


def _float(msg: Mapping[str, object], key: str, path: str, default: float | None = None) -> float:
    if key not in msg and default is not None:
        return default
    v = _req(msg, key, path)
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise WireError(f"{path}{key}: must be a number, got {type(v).__name__}")
    if not math.isfinite(v):
        raise WireError(f"{path}{key}: must be finite, got {v}")
    return float(v)


def _str(msg: Mapping[str, object], key: str, path: str, choices: tuple[str, ...] | None = None) -> str:
    v = _req(msg, key, path)
    if not isinstance(v, str):
        raise WireError(f"{path}{key}: must be a string, got {type(v).__name__}")
    if choices is not None and v not in choices:
        raise WireError(f"{path}{key}: must be one of {list(choices)}, got {v!r}")
    return v


def _bytes(msg: Mapping[str, object], key: str, path: str) -> Binary:
    """A bin field: a read-only view of the payload (no copy; see :mod:`.msgview`)."""
    v = _req(msg, key, path)
    if not isinstance(v, (bytes, bytearray, memoryview)):
        raise WireError(f"{path}{key}: must be binary (msgpack bin), got {type(v).__name__}")
    return v


def _map(v: object, path: str) -> Mapping[str, object]:
    if not isinstance(v, dict):
        raise WireError(f"{path}: must be a map, got {type(v).__name__}")
    return v


def _f32(data: Binary, count: int, field: str) -> np.ndarray:
    if len(data) != 4 * count:
        raise WireError(f"{field}: expected {4 * count} bytes ({count} float32), got {len(data)}")
    return np.frombuffer(data, dtype="<f4", count=count)


def unpack(
    payload: bytes | bytearray | memoryview, limits: WireLimits = DEFAULT_LIMITS, keep: frozenset[str] | None = None
) -> dict[str, object]:
    """Unpack one msgpack message with hard container and total-element limits.

    ``bin`` fields come back as read-only ``memoryview`` slices of ``payload``
    (:mod:`vpp_service.transport.msgview`: no second copy of the images).
    With ``keep``, top-level keys outside it are skipped without being built
    (an unknown key cannot cost more than walking past it).

    Raises
    ------
    WireError
        Too large, truncated/malformed msgpack, or the top level is not a map.
    """
    if not isinstance(payload, (bytes, bytearray, memoryview)):
        raise WireError(f"message: must be bytes, got {type(payload).__name__}")
    n = len(payload)
    if n == 0:
        raise WireError("message: empty")
    if n > limits.max_message_bytes:
        raise WireError(f"message: {n} bytes exceeds the limit of {limits.max_message_bytes}")
    try:
        msg = msgview.loads(
            payload,
            msgview.Limits(
                max_bin_len=n,
                max_str_len=min(n, 1 << 20),
                max_array_len=min(n, 1 << 16),
                max_map_len=min(n, 1 << 12),
                max_elements=limits.max_elements,
            ),
            keep,
        )
    except msgview.MsgViewError as exc:
        raise WireError(f"message: not valid msgpack ({exc})") from None
    if not isinstance(msg, dict):
        raise WireError(f"message: top level must be a map, got {type(msg).__name__}")
    return msg


def _check_version(msg: Mapping[str, object]) -> None:
    v = _int(msg, "v", "", 0, 1 << 31)
    if v != VERSION:
        raise WireError(f"v: unsupported wire version {v} (this build speaks {VERSION})")


# ------------------------------------------------------------------- images
def encode_image(img: np.ndarray, enc: str = "raw", quality: int = 90) -> dict[str, object]:
    """Wire ``Image`` map of an H x W or H x W x C (C = 1 or 3, RGB) uint8 array.

    Parameters
    ----------
    img : ndarray
        uint8 image.
    enc : {"raw", "png", "jpeg"}
        Payload encoding.
    quality : int
        JPEG quality (1..100).

    Raises
    ------
    TypeError, ValueError
        Wrong dtype / shape / encoding.
    """
    if not isinstance(img, np.ndarray):
        raise TypeError(f"img must be a numpy array, got {type(img).__name__}")
    if img.dtype != np.uint8:
        raise TypeError(f"img must be uint8, got {img.dtype}")
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[:, :, 0]
    if img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] != 3) or img.size == 0:
        raise ValueError(f"img must be non-empty H x W or H x W x 3, got shape {img.shape}")
    h, w = img.shape[:2]
    c = 1 if img.ndim == 2 else 3
    if enc == "raw":
        data = np.ascontiguousarray(img).tobytes()
    elif enc in ("png", "jpeg"):
        bgr = img if c == 1 else cv2.cvtColor(img, cv2.COLOR_RGB2BGR)
        params = [cv2.IMWRITE_JPEG_QUALITY, int(quality)] if enc == "jpeg" else [cv2.IMWRITE_PNG_COMPRESSION, 1]
        ok, buf = cv2.imencode(".png" if enc == "png" else ".jpg", bgr, params)
        if not ok:
            raise ValueError(f"could not encode image as {enc}")
        data = buf.tobytes()
    else:
        raise ValueError(f"enc must be 'raw', 'png' or 'jpeg', got {enc!r}")
    return {"h": h, "w": w, "c": c, "dtype": "u8", "enc": enc, "data": data}


def decode_image(m: object, path: str = "image", limits: WireLimits = DEFAULT_LIMITS) -> np.ndarray:
    """Validate and decode a wire ``Image`` map to an H x W (c=1) or H x W x 3 uint8 array.

    Raises
    ------
    WireError
        Any field missing / of the wrong type, sizes over the limits, data length
        not ``h * w * c`` (raw), or an encoded header disagreeing with ``h``/``w``.
    """
    m = _map(m, path)
    p = path + "."
    h = _int(m, "h", p, 1, limits.max_side)
    w = _int(m, "w", p, 1, limits.max_side)
    if h * w > limits.max_pixels:
        raise WireError(f"{p}h: h*w = {h * w} exceeds the limit of {limits.max_pixels}")
    c = _int(m, "c", p, 1, 3)
    if c == 2:
        raise WireError(f"{p}c: must be 1 or 3, got 2")
    _str(m, "dtype", p, ("u8",))
    enc = _str(m, "enc", p, ("raw", "png", "jpeg"))
    data = _bytes(m, "data", p)
    if enc == "raw":
        if len(data) != h * w * c:
            raise WireError(f"{p}data: expected h*w*c = {h * w * c} bytes, got {len(data)}")
        return np.frombuffer(data, dtype=np.uint8).reshape((h, w) if c == 1 else (h, w, 3))
    try:
        hh, ww = encoded_image.png_size(data) if enc == "png" else encoded_image.jpeg_size(data)
        if (hh, ww) != (h, w):
            raise encoded_image.EncodedImageError(f"encoded image is {hh}x{ww}, declared {h}x{w}")
        encoded_image.check_stream(data, "png" if enc == "png" else "jpeg")
    except encoded_image.EncodedImageError as exc:
        raise WireError(f"{p}data: {exc}") from None
    flag = cv2.IMREAD_GRAYSCALE if c == 1 else cv2.IMREAD_COLOR
    decoded = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), flag)
    if decoded is None or decoded.shape[:2] != (h, w):
        raise WireError(f"{p}data: could not decode the {enc} stream")
    return cv2.cvtColor(decoded, cv2.COLOR_BGR2RGB) if c == 3 else decoded


# ------------------------------------------------------------ sparse depth
def encode_depth(frame: StereoFrame, kind: str = "auto") -> dict[str, object] | None:
    """Wire ``SparseDepth`` map of a frame's sparse depth, or None when it has none.

    Parameters
    ----------
    frame : StereoFrame
        Uses ``sensor_depth`` (metres) or ``sparse_disparity`` (pixels).
    kind : {"auto", "points", "disparity_points", "map"}
        ``auto`` sends metric points when the frame has ``sensor_depth``,
        else disparity points. ``map`` sends the full float32 map.
    """
    if kind not in ("auto", "points", "disparity_points", "map"):
        raise ValueError(f"kind must be auto, points, disparity_points or map, got {kind!r}")
    metric = frame.sensor_depth
    disp = frame.sparse_disparity
    if kind == "auto":
        kind = "points" if metric is not None else "disparity_points"
    if kind == "points" and metric is None:
        raise ValueError("kind='points' needs frame.sensor_depth")
    src = metric if kind == "points" or (kind == "map" and metric is not None) else disp
    if src is None:
        return None
    src = np.asarray(src, dtype=np.float32)
    if kind == "map":
        return {
            "kind": "map",
            "h": int(src.shape[0]),
            "w": int(src.shape[1]),
            "unit": "m" if src is metric else "px",
            "data": np.ascontiguousarray(src, dtype="<f4").tobytes(),
        }
    ys, xs = np.nonzero(np.isfinite(src) & (src > 0))
    uv = np.stack([xs, ys], axis=1).astype("<f4")
    vals = src[ys, xs].astype("<f4")
    out = {"kind": kind, "n": len(vals), "uv": uv.tobytes()}
    out["z" if kind == "points" else "d"] = vals.tobytes()
    return out


def points_to_maps(
    uv: np.ndarray,
    vals: np.ndarray,
    h: int,
    w: int,
    keep: str,
    *,
    calib: Calibration | None = None,
    path: str = "depth.",
    values_map: bool = True,
) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Validate sparse points and scatter them into H x W float32 maps (NaN = none).

    Parameters
    ----------
    uv : numpy.ndarray
        n x 2 float32 ``(x, y)`` positions in the left image; each lands on the
        pixel ``(rint(y), rint(x))`` (round half to even) and must lie in
        ``[-0.5, w - 0.5) x [-0.5, h - 0.5)``.
    vals : numpy.ndarray
        n float32 values, finite and > 0.
    h, w : int
        Map size.
    keep : {"min", "max"}
        Which value wins a pixel several points land on (the nearest point:
        the smallest depth, the largest disparity).
    calib : Calibration, optional
        With metric values (``keep="min"``), also return their disparity
        ``f b / z - doffs`` computed in float64 at the winning points (the
        same float32 values as :func:`vpp_service.vpp.depth_to_disparity` of
        the metric map, without its four passes over the whole map); pixels
        where it is ``<= 0`` stay NaN.
    path : str
        Field prefix for error messages.
    values_map : bool
        False (only with ``calib`` and ``keep="min"``): build the disparity map
        alone and return None for the values map (the disparity map is the
        same: the largest disparity of a pixel belongs to its smallest depth).

    Returns
    -------
    (values_map or None, disparity_map or None)

    Raises
    ------
    WireError
        Non-finite coordinates, points outside the image, values not finite
        and > 0 (checked in that order over all points).

    Notes
    -----
    One pass in Cython (``_points.scatter_points``) validates and scatters
    all points, instead of several NumPy passes over them.
    """
    if keep not in ("min", "max"):
        raise ValueError(f"keep must be 'min' or 'max', got {keep!r}")
    d_calib = calib if keep == "min" else None  # disparities of metric points only
    if not values_map and d_calib is None:
        raise ValueError('values_map=False needs keep="min" and a calib (it builds the disparity map alone)')
    out = np.full((h, w), np.nan, dtype=np.float32) if values_map else _NO_MAP
    out_d = np.full((h, w), np.nan, dtype=np.float32) if d_calib is not None else _NO_MAP
    fb, doffs = (d_calib.f * d_calib.baseline, d_calib.doffs) if d_calib is not None else (0.0, 0.0)
    bad = _points.scatter_points(
        np.ascontiguousarray(uv, dtype=np.float32).reshape(-1),
        np.ascontiguousarray(vals, dtype=np.float32),
        keep == "min",
        out,
        out_d,
        float(fb),
        float(doffs),
    )
    if bad & _points.BAD_UV:
        raise WireError(f"{path}uv: coordinates must be finite")
    if bad & _points.OUTSIDE:
        raise WireError(f"{path}uv: points must lie inside the {w}x{h} left image")
    if bad:
        raise WireError(f"{path}{'z' if keep == 'min' else 'd'}: values must be finite and > 0")
    return (out if values_map else None), (out_d if d_calib is not None else None)


_NO_MAP = np.empty((0, 0), np.float32)


def decode_depth(
    m: object,
    h: int,
    w: int,
    path: str = "depth",
    *,
    limits: WireLimits = DEFAULT_LIMITS,
    calib: Calibration | None = None,
    metric_map: bool = True,
) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Validate a ``SparseDepth`` map; return ``(sensor_depth_m, sparse_disparity_px)``.

    Exactly one of the two is not None, except for metric ``points`` with a
    ``calib``: their disparity ``f b / z - doffs`` is then also computed, at the
    points only (the same float32 values as
    :func:`vpp_service.vpp.depth_to_disparity` of the metric map, which costs
    four passes over the whole map; points with ``d <= 0`` are left out).
    With ``metric_map=False`` such points come back as their disparity alone
    (``sensor_depth_m`` None: one H x W map built instead of two).
    Points are rounded to the nearest pixel; when two land on one pixel the
    nearest (smaller depth / larger disparity) wins.

    Raises
    ------
    WireError
        Bad kind, counts, byte lengths, non-finite or non-positive values,
        points outside the ``h`` x ``w`` image, map size not ``h`` x ``w``.
    """
    m = _map(m, path)
    p = path + "."
    if h * w > limits.max_pixels:
        raise WireError(f"{p}h: h*w = {h * w} exceeds the limit of {limits.max_pixels}")
    kind = _str(m, "kind", p, ("points", "disparity_points", "map"))
    if kind == "map":
        mh = _int(m, "h", p, 1, limits.max_side)
        mw = _int(m, "w", p, 1, limits.max_side)
        if (mh, mw) != (h, w):
            raise WireError(f"{p}h: depth map is {mh}x{mw}, image is {h}x{w}")
        unit = _str(m, "unit", p, ("m", "px"))
        arr = _f32(_bytes(m, "data", p), h * w, p + "data").reshape(h, w)
        if np.isinf(arr).any() or (arr < 0).any():
            raise WireError(f"{p}data: values must be >= 0 or NaN (0/NaN = none)")
        arr = arr.astype(np.float32)
        arr[arr == 0] = np.nan
        return (arr, None) if unit == "m" else (None, arr)
    n = _int(m, "n", p, 0, min(limits.max_points, h * w * 4))
    uv = _f32(_bytes(m, "uv", p), 2 * n, p + "uv").reshape(n, 2)
    key = "z" if kind == "points" else "d"
    vals = _f32(_bytes(m, key, p), n, p + key)
    if kind != "points":
        return None, points_to_maps(uv, vals, h, w, "max", path=p)[0]
    return points_to_maps(uv, vals, h, w, "min", calib=calib, path=p, values_map=metric_map or calib is None)


def _encode_gt(gt: np.ndarray) -> dict[str, object]:
    gt = np.asarray(gt, dtype="<f4")
    return {"h": int(gt.shape[0]), "w": int(gt.shape[1]), "data": np.ascontiguousarray(gt).tobytes()}


def _decode_gt(m: object, h: int, w: int) -> np.ndarray:
    m = _map(m, "gt")
    gh = _int(m, "h", "gt.", 1, 1 << 16)
    gw = _int(m, "w", "gt.", 1, 1 << 16)
    if (gh, gw) != (h, w):
        raise WireError(f"gt.h: ground truth is {gh}x{gw}, image is {h}x{w}")
    arr = _f32(_bytes(m, "data", "gt."), h * w, "gt.data").reshape(h, w).astype(np.float32)
    arr[~np.isfinite(arr) | (arr <= 0)] = np.nan
    return arr


def _decode_calib(m: object) -> Calibration:
    m = _map(m, "calib")
    f = _float(m, "f", "calib.")
    b = _float(m, "baseline", "calib.")
    doffs = _float(m, "doffs", "calib.", 0.0)
    if f <= 0:
        raise WireError(f"calib.f: must be > 0, got {f}")
    if b <= 0:
        raise WireError(f"calib.baseline: must be > 0, got {b}")
    cx = _float(m, "cx", "calib.") if "cx" in m else None
    cy = _float(m, "cy", "calib.") if "cy" in m else None
    return Calibration(f=f, baseline=b, doffs=doffs, cx=cx, cy=cy)


def _header(msg: Mapping[str, object]) -> tuple[str, int, int]:
    _check_version(msg)
    rig = _str(msg, "rig", "")
    if not rig or len(rig) > 256:
        raise WireError("rig: must be a non-empty string of at most 256 characters")
    seq = _int(msg, "seq", "", 0, (1 << 63) - 1)
    stamp = _int(msg, "stamp_ns", "", 0, (1 << 63) - 1)
    return rig, seq, stamp


# ------------------------------------------------------------------- frames
#: Top-level keys an ``in/frame`` / separate-topics decoder reads (others are skipped unbuilt).
_FRAME_KEYS = frozenset({"v", "rig", "seq", "stamp_ns", "left", "right", "calib", "rectified", "depth", "gt"})
_PART_KEYS = frozenset({"v", "rig", "seq", "stamp_ns", "image", "calib", "rectified", "gt", "depth", "h", "w"})


def _decode_rectified(msg: Mapping[str, object]) -> bool:
    """The optional ``rectified`` flag (a rig with ``[rectify]`` skips the remap of such a frame)."""
    v = msg.get("rectified", False)
    if not isinstance(v, bool):
        raise WireError(f"rectified: must be true or false, got {type(v).__name__}")
    return v


def encode_frame(frame: StereoFrame, enc: str = "raw", depth_kind: str = "auto", include_gt: bool = True) -> bytes:
    """Serialize a :class:`StereoFrame` as a v1 ``in/frame`` message.

    Parameters
    ----------
    frame : StereoFrame
        ``calib`` is optional (a raw frame of a rig the service rectifies needs none);
        ``meta["rectified"] = True`` is sent as ``"rectified": true``. Sparse depth and
        ground truth are optional.
    enc : {"raw", "png", "jpeg"}
        Image encoding.
    depth_kind : str
        See :func:`encode_depth`.
    include_gt : bool
        Send ``frame.gt_disparity`` in the ``gt`` extension field.

    Raises
    ------
    TypeError, ValueError
        Not a frame, mismatched shapes.
    """
    if not isinstance(frame, StereoFrame):
        raise TypeError(f"frame must be a StereoFrame, got {type(frame).__name__}")
    if frame.left.shape != frame.right.shape:
        raise ValueError(f"frame.left {frame.left.shape} and frame.right {frame.right.shape} differ")
    msg: dict[str, object] = {
        "v": VERSION,
        "rig": frame.rig,
        "seq": int(frame.seq),
        "stamp_ns": int(frame.stamp_ns),
        "left": encode_image(frame.left, enc),
        "right": encode_image(frame.right, enc),
    }
    if frame.calib is not None:
        msg["calib"] = frame.calib.to_dict()
    if frame.meta.get("rectified") is True:
        msg["rectified"] = True
    depth = encode_depth(frame, depth_kind)
    if depth is not None:
        msg["depth"] = depth
    if include_gt and frame.gt_disparity is not None:
        msg["gt"] = _encode_gt(frame.gt_disparity)
    return msgpack.packb(msg, use_bin_type=True)


def decode_frame(payload: bytes, limits: WireLimits = DEFAULT_LIMITS, *, metric_map: bool = True) -> StereoFrame:
    """Parse and fully validate an ``in/frame`` message into a :class:`StereoFrame`.

    Metric depth arrives as ``sensor_depth``, and metric points also as their
    ``sparse_disparity`` (see :func:`decode_depth`; a metric map is converted
    by the pipeline); disparity points/maps as ``sparse_disparity``. With
    ``metric_map=False`` metric points arrive as their ``sparse_disparity``
    only (``sensor_depth`` None), which is all the fusion reads of them.
    ``calib`` is optional (None when absent); ``"rectified": true`` becomes
    ``meta["rectified"] = True``.

    Raises
    ------
    WireError
        Anything wrong, naming the field.
    """
    msg = unpack(payload, limits, _FRAME_KEYS)
    rig, seq, stamp = _header(msg)
    left = decode_image(_req(msg, "left", ""), "left", limits)
    right = decode_image(_req(msg, "right", ""), "right", limits)
    if left.shape != right.shape:
        raise WireError(f"right: shape {right.shape} differs from left {left.shape}")
    calib = _decode_calib(msg["calib"]) if msg.get("calib") is not None else None
    rectified = _decode_rectified(msg)
    h, w = left.shape[:2]
    sensor = disp = gt = None
    if msg.get("depth") is not None:
        sensor, disp = decode_depth(msg["depth"], h, w, "depth", limits=limits, calib=calib, metric_map=metric_map)
    if msg.get("gt") is not None:
        gt = _decode_gt(msg["gt"], h, w)
    return StereoFrame(
        left=left,
        right=right,
        calib=calib,
        sparse_disparity=disp,
        sensor_depth=sensor,
        gt_disparity=gt,
        rig=rig,
        seq=seq,
        stamp_ns=stamp,
        meta={"rectified": True} if rectified else {},
    )


# -------------------------------------------- separate-topics part messages
def encode_part(frame: StereoFrame, part: str, enc: str = "raw", depth_kind: str = "auto") -> bytes | None:
    """One separate-topics message (``part`` = "left", "right" or "depth").

    ``left`` carries the calibration when the frame has one, the ``rectified`` flag and
    ground truth (as an extension); ``depth`` returns None when the frame has no sparse depth.
    """
    base: dict[str, object] = {"v": VERSION, "rig": frame.rig, "seq": int(frame.seq), "stamp_ns": int(frame.stamp_ns)}
    if part in ("left", "right"):
        base["image"] = encode_image(frame.left if part == "left" else frame.right, enc)
        if part == "left":
            if frame.calib is not None:
                base["calib"] = frame.calib.to_dict()
            if frame.meta.get("rectified") is True:
                base["rectified"] = True
            if frame.gt_disparity is not None:
                base["gt"] = _encode_gt(frame.gt_disparity)
    elif part == "depth":
        d = encode_depth(frame, depth_kind)
        if d is None:
            return None
        base["depth"] = d
        base["h"], base["w"] = int(frame.left.shape[0]), int(frame.left.shape[1])
    else:
        raise ValueError(f"part must be 'left', 'right' or 'depth', got {part!r}")
    return msgpack.packb(base, use_bin_type=True)


@dataclass
class Part:
    """A decoded separate-topics message (one of left / right / depth)."""

    part: str
    rig: str
    seq: int
    stamp_ns: int
    image: np.ndarray | None = None
    calib: Calibration | None = None
    gt: np.ndarray | None = None
    sensor_depth: np.ndarray | None = None
    sparse_disparity: np.ndarray | None = None
    rectified: bool = False


def decode_part(payload: bytes, part: str, limits: WireLimits = DEFAULT_LIMITS) -> Part:
    """Parse and validate a separate-topics message for ``part``.

    Raises
    ------
    WireError
        Anything wrong, naming the field.
    """
    if part not in ("left", "right", "depth"):
        raise ValueError(f"part must be 'left', 'right' or 'depth', got {part!r}")
    msg = unpack(payload, limits, _PART_KEYS)
    rig, seq, stamp = _header(msg)
    out = Part(part=part, rig=rig, seq=seq, stamp_ns=stamp)
    if part in ("left", "right"):
        out.image = decode_image(_req(msg, "image", ""), "image", limits)
        if part == "left":
            out.calib = _decode_calib(msg["calib"]) if msg.get("calib") is not None else None
            out.rectified = _decode_rectified(msg)
            if msg.get("gt") is not None:
                out.gt = _decode_gt(msg["gt"], *out.image.shape[:2])
    else:
        h = _int(msg, "h", "", 1, limits.max_side)
        w = _int(msg, "w", "", 1, limits.max_side)
        if h * w > limits.max_pixels:
            raise WireError(f"h: h*w = {h * w} exceeds the limit of {limits.max_pixels}")
        out.sensor_depth, out.sparse_disparity = decode_depth(_req(msg, "depth", ""), h, w, "depth", limits=limits)
    return out


def assemble(left: Part, right: Part, depth: Part | None) -> StereoFrame:
    """Join synchronized parts into a :class:`StereoFrame` (left's seq/stamp win).

    Raises
    ------
    WireError
        Image shapes differ, or the depth size differs from the images.
    """
    if left.image is None or right.image is None:
        raise ValueError("left and right must be image parts (decode_part of 'left' / 'right')")
    if left.image.shape != right.image.shape:
        raise WireError(f"right.image: shape {right.image.shape} differs from left {left.image.shape}")
    sensor = disp = None
    if depth is not None:
        dm = depth.sensor_depth if depth.sensor_depth is not None else depth.sparse_disparity
        if dm is None:
            raise ValueError("depth must be a depth part (decode_part of 'depth')")
        if dm.shape != left.image.shape[:2]:
            raise WireError(f"depth.h: depth is {dm.shape}, image is {left.image.shape[:2]}")
        sensor, disp = depth.sensor_depth, depth.sparse_disparity
    return StereoFrame(
        left=left.image,
        right=right.image,
        calib=left.calib,
        sparse_disparity=disp,
        sensor_depth=sensor,
        gt_disparity=left.gt,
        rig=left.rig,
        seq=left.seq,
        stamp_ns=left.stamp_ns,
        meta={"rectified": True} if left.rectified else {},
    )


# ------------------------------------------------------------------ outputs
def _bin_header(n: int) -> bytes:
    """Msgpack ``bin`` header of an ``n``-byte payload (the smallest form, as ``packb`` writes it)."""
    if n < 1 << 8:
        return bytes((0xC4, n))
    if n < 1 << 16:
        return b"\xc5" + n.to_bytes(2, "big")
    return b"\xc6" + n.to_bytes(4, "big")


def _map_parts(fields: Mapping[str, object], blob_key: str, blob: bytes) -> list[bytes]:
    """``packb({**fields, blob_key: blob})`` as two parts: everything up to the blob, and the blob."""
    pk = msgpack.Packer(use_bin_type=True, autoreset=False)
    pk.pack_map_header(len(fields) + 1)
    for k, v in fields.items():
        pk.pack(k)
        pk.pack(v)
    pk.pack(blob_key)
    return [pk.bytes() + _bin_header(len(blob)), blob]


def _map_message(result: FusionResult, arr: np.ndarray, extra: Mapping[str, object]) -> list[bytes]:
    fr = result.frame
    msg = {
        "v": VERSION,
        "rig": fr.rig,
        "seq": int(fr.seq),
        "stamp_ns": int(fr.stamp_ns),
        "h": int(arr.shape[0]),
        "w": int(arr.shape[1]),
        "dtype": "f32",
        "calib": fr.calib.to_dict() if fr.calib is not None else None,
        "timing_ms": {str(k): float(v) for k, v in result.timing_ms.items()},
    }
    msg.update(extra)
    # the map's bytes stay a separate part (one copy out of the array): a
    # publisher writes the parts straight into its buffer without joining them
    return _map_parts(msg, "data", np.ascontiguousarray(arr, dtype="<f4").tobytes())


def encode_output_parts(
    result: FusionResult, name: str, enc: str = "raw", points_stride: int = DEFAULT_STRIDE
) -> list[bytes] | None:
    """:func:`encode_output` as a list of byte strings whose concatenation is the message.

    The float maps' data is its own part: no copy to join it.
    """
    if name not in OUTPUTS:
        raise ValueError(f"name must be one of {OUTPUTS}, got {name!r}")
    fr = result.frame
    if name in ("sparse", "points"):  # point sets: the sparse input, the output cloud
        return _sparse_parts(fr) if name == "sparse" else encode_points_parts(result, points_stride)
    if name == "disparity":
        extra = {}
        if result.metrics:
            extra["metrics"] = {k: float(v) for k, v in result.metrics.items()}
        if result.vpp_stats:
            extra["vpp"] = {
                k: (int(v) if isinstance(v, (int, np.integer)) else float(v))
                for k, v in result.vpp_stats.items()
                if isinstance(v, (int, float, np.number))
            }
        return _map_message(result, result.disparity, extra)
    if name in ("depth", "confidence"):
        arr = result.depth if name == "depth" else result.confidence
        return None if arr is None else _map_message(result, arr, {})
    img = result.left_vpp if name == "left_vpp" else result.right_vpp
    if img is None:
        return None
    msg = {
        "v": VERSION,
        "rig": fr.rig,
        "seq": int(fr.seq),
        "stamp_ns": int(fr.stamp_ns),
        "image": encode_image(img, enc),
    }
    return [msgpack.packb(msg, use_bin_type=True)]


def _sparse_parts(fr: StereoFrame) -> list[bytes] | None:
    """The ``out/sparse`` message of a frame's sparse input points (None without any)."""
    pts = sparse_to_points(fr.sparse_disparity)
    if pts is None:
        return None
    h, w = fr.left.shape[:2]
    fields = {"v": VERSION, "rig": fr.rig, "seq": int(fr.seq), "stamp_ns": int(fr.stamp_ns), "h": h, "w": w}
    return _map_parts({**fields, "n": len(pts), "dtype": "f32"}, "data", pts.astype("<f4").tobytes())


def encode_output(
    result: FusionResult, name: str, enc: str = "raw", points_stride: int = DEFAULT_STRIDE
) -> bytes | None:
    """Serialize one of :data:`OUTPUTS` (``disparity``, ``depth``, ``confidence``, ``points``, ...).

    Returns None when the result does not have that output (e.g. no depth
    without calibration, no painted pair when VPP was skipped, no confidence
    when nothing asked for it). The
    ``disparity`` message also carries ``metrics`` (vs ground truth) and
    ``vpp`` (VPP counters) as extensions when known. ``points_stride``: the
    ``points`` output's decimation (:mod:`vpp_service.transport.backproject`).
    """
    parts = encode_output_parts(result, name, enc, points_stride)
    return None if parts is None else b"".join(parts)


@dataclass
class OutputMap:
    """A decoded ``out/disparity``, ``out/depth`` or ``out/confidence`` message."""

    rig: str
    seq: int
    stamp_ns: int
    data: np.ndarray
    calib: Calibration | None
    timing_ms: dict[str, float]
    metrics: dict[str, float]
    extra: dict[str, object]


def _numbers(m: Mapping[str, object]) -> dict[str, float]:
    """The ``timing_ms`` / ``metrics`` map as floats; raises WireError unless it maps names to numbers."""
    out: dict[str, float] = {}
    for k, v in m.items():
        if not isinstance(k, str) or isinstance(v, bool) or not isinstance(v, (int, float)):
            raise WireError(f"timing_ms/metrics.{k}: must map names to numbers")
        out[k] = float(v)
    return out


def decode_output(payload: bytes, limits: WireLimits = DEFAULT_LIMITS) -> OutputMap:
    """Parse and validate an ``out/disparity``, ``out/depth`` or ``out/confidence`` message.

    Raises
    ------
    WireError
        Anything wrong, naming the field.
    """
    msg = unpack(payload, limits)
    rig, seq, stamp = _header(msg)
    h = _int(msg, "h", "", 1, limits.max_side)
    w = _int(msg, "w", "", 1, limits.max_side)
    _str(msg, "dtype", "", ("f32",))
    data = _f32(_bytes(msg, "data", ""), h * w, "data").reshape(h, w)
    calib = _decode_calib(msg["calib"]) if msg.get("calib") is not None else None
    timing = _numbers(_map(msg.get("timing_ms", {}), "timing_ms"))
    metrics = _numbers(_map(msg.get("metrics", {}), "metrics"))
    extra = {
        k: v
        for k, v in msg.items()
        if k not in ("v", "rig", "seq", "stamp_ns", "h", "w", "dtype", "data", "calib", "timing_ms", "metrics")
    }
    return OutputMap(
        rig=rig,
        seq=seq,
        stamp_ns=stamp,
        data=data,
        calib=calib,
        timing_ms=timing,
        metrics=metrics,
        extra=extra,
    )


def sparse_to_points(sparse_disparity: np.ndarray | None) -> np.ndarray | None:
    """Valid entries (finite, > 0) of a sparse disparity map as n x 3 float32 rows ``(x, y, d)``, raster order."""
    if sparse_disparity is None:
        return None
    ys, xs = np.nonzero(np.isfinite(sparse_disparity) & (sparse_disparity > 0))
    return np.stack([xs, ys, sparse_disparity[ys, xs]], axis=1).astype(np.float32)


@dataclass
class OutputPoints:
    """A decoded ``out/sparse`` message: ``points`` is n x 3 float32 ``(x, y, disparity)`` inside ``w`` x ``h``."""

    rig: str
    seq: int
    stamp_ns: int
    h: int
    w: int
    points: np.ndarray


def decode_output_points(payload: bytes, limits: WireLimits = DEFAULT_LIMITS) -> OutputPoints:
    """Parse and validate an ``out/sparse`` message.

    Raises
    ------
    WireError
        Anything wrong, naming the field (points must lie inside the image, disparities finite and > 0).
    """
    msg = unpack(payload, limits)
    rig, seq, stamp = _header(msg)
    h = _int(msg, "h", "", 1, limits.max_side)
    w = _int(msg, "w", "", 1, limits.max_side)
    n = _int(msg, "n", "", 0, limits.max_points)
    _str(msg, "dtype", "", ("f32",))
    pts = _f32(_bytes(msg, "data", ""), 3 * n, "data").reshape(n, 3)
    if not np.isfinite(pts).all():
        raise WireError("data: values must be finite")
    if n and (pts[:, 0].min() < 0 or pts[:, 0].max() > w - 1 or pts[:, 1].min() < 0 or pts[:, 1].max() > h - 1):
        raise WireError(f"data: points must lie inside the {w}x{h} image")
    if n and pts[:, 2].min() <= 0:
        raise WireError("data: disparities must be > 0")
    return OutputPoints(rig=rig, seq=seq, stamp_ns=stamp, h=h, w=w, points=pts)


# ------------------------------------------------------------ points output
def _blobs_parts(fields: Mapping[str, object], blobs: Mapping[str, bytes]) -> list[bytes]:
    """``packb({**fields, **blobs})`` as parts: each blob its own part, the bytes around it between."""
    pk = msgpack.Packer(use_bin_type=True, autoreset=False)
    pk.pack_map_header(len(fields) + len(blobs))
    for k, v in fields.items():
        pk.pack(k)
        pk.pack(v)
    parts: list[bytes] = []
    for key, blob in blobs.items():
        pk.pack(key)
        parts += [pk.bytes() + _bin_header(len(blob)), blob]
        pk.reset()
    return parts


def encode_points_parts(result: FusionResult, stride: int = DEFAULT_STRIDE) -> list[bytes] | None:
    """The ``out/points`` message of ``result`` as parts (None without metric depth).

    The valid pixels of the (depth-clipped) depth map on every ``stride``-th row and
    column, back-projected by :func:`~vpp_service.transport.backproject.depth_to_points`
    and coloured from the left image, in raster order: an ``xyz`` blob (float32 n x 3)
    and an ``rgb`` blob (uint8 n x 3) after the header fields.
    """
    fr = result.frame
    if result.depth is None or fr.calib is None:
        return None
    xyz, rgb = depth_to_points(np.asarray(result.depth), fr.left, fr.calib, stride=stride)
    h, w = result.depth.shape
    fields = {
        "v": VERSION,
        "rig": fr.rig,
        "seq": int(fr.seq),
        "stamp_ns": int(fr.stamp_ns),
        "h": int(h),
        "w": int(w),
        "stride": int(stride),
        "calib": fr.calib.to_dict(),
        "n": len(xyz),
    }
    blobs = {"xyz": np.ascontiguousarray(xyz, dtype="<f4").tobytes(), "rgb": rgb.tobytes()}
    return _blobs_parts(fields, blobs)


@dataclass
class OutputCloud:
    """A decoded ``out/points`` message.

    Attributes
    ----------
    rig, seq, stamp_ns
        The frame's header.
    h, w : int
        Size of the depth map the points come from.
    stride : int
        Every ``stride``-th row and column of it.
    calib : Calibration
        The rectified left camera the points are in.
    xyz : ndarray
        N x 3 float32 ``(x, y, z)`` metres: x right, y down, z forward (> 0).
    rgb : ndarray
        N x 3 uint8 colours.
    """

    rig: str
    seq: int
    stamp_ns: int
    h: int
    w: int
    stride: int
    calib: Calibration
    xyz: np.ndarray
    rgb: np.ndarray


def decode_output_cloud(payload: bytes, limits: WireLimits = DEFAULT_LIMITS) -> OutputCloud:
    """Parse and validate an ``out/points`` message.

    Raises
    ------
    WireError
        Anything wrong, naming the field (blob lengths exactly ``12 n`` / ``3 n``, points
        finite with ``z > 0``, ``n`` at most the strided grid's size).
    """
    msg = unpack(payload, limits)
    rig, seq, stamp = _header(msg)
    h = _int(msg, "h", "", 1, limits.max_side)
    w = _int(msg, "w", "", 1, limits.max_side)
    stride = _int(msg, "stride", "", 1, limits.max_side)
    grid = -(-h // stride) * -(-w // stride)
    n = _int(msg, "n", "", 0, min(grid, limits.max_points))
    calib = _decode_calib(_req(msg, "calib", ""))
    xyz = _f32(_bytes(msg, "xyz", ""), 3 * n, "xyz").reshape(n, 3)
    rgb_b = _bytes(msg, "rgb", "")
    if len(rgb_b) != 3 * n:
        raise WireError(f"rgb: {len(rgb_b)} bytes, need {3 * n} (n x 3 uint8)")
    if not np.isfinite(xyz).all():
        raise WireError("xyz: coordinates must be finite")
    if n and xyz[:, 2].min() <= 0:
        raise WireError("xyz: z must be > 0 (points in front of the camera)")
    rgb = np.frombuffer(rgb_b, np.uint8).reshape(n, 3)
    return OutputCloud(rig=rig, seq=seq, stamp_ns=stamp, h=h, w=w, stride=stride, calib=calib, xyz=xyz, rgb=rgb)


def decode_output_image(payload: bytes, limits: WireLimits = DEFAULT_LIMITS) -> tuple[int, np.ndarray]:
    """Parse an ``out/left_vpp`` / ``out/right_vpp`` message; returns ``(seq, image)``."""
    msg = unpack(payload, limits)
    _, seq, _ = _header(msg)
    return seq, decode_image(_req(msg, "image", ""), "image", limits)


__all__ = [
    "DEFAULT_LIMITS",
    "DEFAULT_PREFIX",
    "OUTPUTS",
    "VERSION",
    "OutputCloud",
    "OutputMap",
    "OutputPoints",
    "Part",
    "WireError",
    "WireLimits",
    "assemble",
    "decode_depth",
    "decode_frame",
    "decode_image",
    "decode_output",
    "decode_output_cloud",
    "decode_output_image",
    "decode_output_points",
    "decode_part",
    "encode_depth",
    "encode_frame",
    "encode_image",
    "encode_output",
    "encode_output_parts",
    "encode_part",
    "encode_points_parts",
    "points_to_maps",
    "sparse_to_points",
    "topic",
    "unpack",
]
