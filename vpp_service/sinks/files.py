"""The ``files`` sink: write every result to disk as image/array files.

Disparity formats (``formats`` option, any subset):

``png16``
    16-bit PNG, value = round(disparity * 256) (KITTI convention), 0 = invalid:
    exactly the pixels that are NaN in ``npy`` (and ``+inf`` in ``pfm``) once the
    service's depth clip (:mod:`vpp_service.matchers.depth_clip`) has made every
    disparity outside the valid range NaN, since a valid disparity is then > 0.
    Valid disparities are clamped to ``[1, 65535]`` so a tiny valid value never
    reads back as invalid and values above 255.996 px saturate.
``pfm``
    float32 little-endian PFM, rows stored bottom-up (Middlebury convention);
    invalid pixels (NaN) are written as ``+inf``, as in Middlebury ground truth.
``npy``
    float32 ``.npy``; invalid = NaN (exactly the in-memory convention).

Extras: ``painted`` saves the VPP-painted pair as 8-bit PNGs, ``depth`` saves
metric depth (metres, NaN invalid) as float32 ``.npy``, and ``preview`` saves a
colour-mapped 8-bit RGB PNG of the disparity (turbo, near = red, invalid = black)
for looking at: the 16-bit PNGs look black in an ordinary image viewer. Its range
is ``[0, preview_max_disparity]`` (fixed, comparable between frames) or, when that
is 0, each frame's own range of valid values. ``points`` saves the point cloud as a
binary little-endian PLY (:mod:`vpp_service.sinks.ply`: ``x y z`` float32 metres in the
rectified left camera, x right, y down, z forward; ``red green blue`` uchar from the left
image): the valid (depth-clipped) pixels on every ``points_stride``-th row and column,
back-projected by :mod:`vpp_service.transport.backproject` (calibrated frames only).
``confidence`` saves the per-pixel confidence of the disparity (0..1, 0 = no answer)
as float32 ``.npy`` and as a 16-bit PNG, value = round(confidence * 65535)
(:func:`encode_confidence_png16`).

File names are ``<pattern>_<what>.<ext>`` where ``pattern`` (default
``{rig}_{seq:06d}``) may use ``rig``, ``seq``, ``stamp_ns`` and ``name``, and
``<what>`` is ``disparity``, ``disparity_preview``, ``depth``, ``confidence``, ``points``,
``left_vpp`` or ``right_vpp``.

Every file is written to a temporary name in the same folder and then renamed
into place, so readers never see a partial file. After :meth:`FilesSink.open`
succeeded, write failures (disk full, existing file with ``overwrite = false``,
bad arrays) are logged and counted in ``stats()["errors"]``, never raised.
"""

from __future__ import annotations

import io
import logging
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import cv2
import numpy as np

from vpp_service.datasets.pfm import write_pfm
from vpp_service.frame import FusionResult
from vpp_service.settings import Each, NonEmpty, OneOf, Options, Range, Satisfies, Unique
from vpp_service.sinks.base import SINKS, SinkContext
from vpp_service.sinks.colorize import colorize_disparity
from vpp_service.sinks.folder import PATTERN_RULE, FolderSink, check_pattern, path_inside, write_atomic
from vpp_service.sinks.ply import encode_ply
from vpp_service.transport.backproject import DEFAULT_STRIDE, MAX_STRIDE, depth_to_points

log = logging.getLogger(__name__)

#: Supported disparity formats.
FORMATS = ("png16", "pfm", "npy")
_EXT = {"png16": ".png", "pfm": ".pfm", "npy": ".npy"}


@dataclass(frozen=True)
class FilesSinkOptions(Options):
    """Options of the ``files`` sink.

    Attributes
    ----------
    dir : str
        Output folder (required); must exist and be writable unless
        ``create_dir`` is true.
    formats : tuple of str
        Non-empty subset of ``("png16", "pfm", "npy")``; default ``("png16",)``.
    painted : bool
        Also save the painted pair (``left_vpp``/``right_vpp``) as PNG when present.
    depth : bool
        Also save metric depth as float32 ``.npy`` when present.
    confidence : bool
        Also save the per-pixel confidence as float32 ``.npy`` and 16-bit PNG
        (``<stem>_confidence.npy`` / ``.png``); the service computes it only then.
    pattern : str
        File name stem, a ``str.format`` pattern over ``rig``, ``seq``,
        ``stamp_ns``, ``name``; must not contain path separators.
    overwrite : bool
        Replace existing files (default false: an existing file is an error,
        counted, and the new file is not written).
    create_dir : bool
        Create ``dir`` (with parents) at open instead of failing when missing.
    preview : bool
        Also save a colour-mapped RGB PNG of the disparity (``<stem>_disparity_preview.png``).
    preview_max_disparity : float
        Top of the preview's colour range (pixels, >= 0); 0 = each frame's own range.
    points : bool
        Also save the point cloud as binary PLY (``<stem>_points.ply``) when the frame is calibrated.
    points_stride : int
        Every ``points_stride``-th row and column of the depth map becomes a point (1 = every
        pixel; the default 4 keeps a 720p cloud under 57 600 points).
    """

    dir: Annotated[str, NonEmpty()]
    formats: Annotated[tuple[str, ...], NonEmpty(), Unique(), Each(OneOf(*FORMATS))] = ("png16",)
    painted: bool = False
    depth: bool = False
    confidence: bool = False
    pattern: Annotated[str, Satisfies(check_pattern, PATTERN_RULE)] = "{rig}_{seq:06d}"
    overwrite: bool = False
    create_dir: bool = False
    preview: bool = False
    preview_max_disparity: Annotated[float, Range(0.0)] = 0.0
    points: bool = False
    points_stride: Annotated[int, Range(1, MAX_STRIDE)] = DEFAULT_STRIDE


def _check_disparity(disparity: object) -> np.ndarray:
    if not isinstance(disparity, np.ndarray):
        raise TypeError(f"disparity: must be a numpy ndarray, got {type(disparity).__name__}")
    if not (np.issubdtype(disparity.dtype, np.floating) or np.issubdtype(disparity.dtype, np.integer)):
        raise TypeError(f"disparity: must have a real numeric dtype, got {disparity.dtype}")
    if disparity.ndim != 2 or disparity.size == 0:
        raise ValueError(f"disparity: must be a non-empty H x W array, got shape {disparity.shape}")
    return disparity


def encode_png16(disparity: np.ndarray) -> bytes:
    """Encode a disparity map as a KITTI-style 16-bit PNG.

    Parameters
    ----------
    disparity : ndarray
        H x W real array; NaN, inf and values <= 0 are invalid.

    Returns
    -------
    bytes
        PNG file contents; pixel = clip(round(d * 256), 1, 65535), 0 = invalid.

    Raises
    ------
    TypeError, ValueError
        If ``disparity`` is not a non-empty 2-D real array.
    """
    d = _check_disparity(disparity).astype(np.float64, copy=False)
    valid = np.isfinite(d) & (d > 0)
    q = np.zeros(d.shape, np.uint16)
    q[valid] = np.clip(np.rint(d[valid] * 256.0), 1, 65535).astype(np.uint16)
    ok, buf = cv2.imencode(".png", q)
    if not ok:  # pragma: no cover - OpenCV always encodes uint16 PNG
        raise RuntimeError("OpenCV failed to encode a 16-bit PNG")
    return buf.tobytes()


def decode_png16(data: bytes) -> np.ndarray:
    """Decode :func:`encode_png16` output back to float32 disparity (NaN invalid).

    Parameters
    ----------
    data : bytes
        PNG file contents (16-bit, one channel).

    Returns
    -------
    ndarray
        H x W float32, ``value / 256``; 0 becomes NaN.

    Raises
    ------
    ValueError
        If ``data`` is not a single-channel 16-bit PNG.
    """
    if not isinstance(data, (bytes, bytearray, memoryview)) or len(data) == 0:
        raise ValueError("data: must be non-empty PNG bytes")
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if img is None or img.dtype != np.uint16 or img.ndim != 2:
        raise ValueError("data: not a single-channel 16-bit PNG")
    out = img.astype(np.float32) / np.float32(256.0)
    out[img == 0] = np.nan
    return out


def _float_nan(a: np.ndarray) -> np.ndarray:
    """float32 copy with every non-finite value set to NaN."""
    out = np.array(a, dtype=np.float32, copy=True)
    out[~np.isfinite(out)] = np.nan
    return out


@SINKS.register("files")
class FilesSink(FolderSink):
    """Write disparity (and optionally painted pair and depth) files per result.

    Parameters
    ----------
    options : FilesSinkOptions
        Parsed options (see :func:`vpp_service.sinks.base.build_sink`).
    context : SinkContext
        Service context; ``context.rig`` is used when a frame has no rig name.

    Examples
    --------
    >>> sink = build_sink("files", {"dir": "/tmp/out", "formats": ["png16", "npy"]})  # doctest: +SKIP
    >>> with sink:
    ...     sink.write(result)
    """

    Options = FilesSinkOptions
    options: FilesSinkOptions

    @classmethod
    def needs_depth(cls, options: FilesSinkOptions) -> bool:
        """True when the ``depth`` or ``points`` files are written."""
        return options.depth or options.points

    @classmethod
    def needs_confidence(cls, options: FilesSinkOptions) -> bool:
        """True when the ``confidence`` files are written."""
        return options.confidence

    DIR_KEY = "sinks.files.dir"
    DIR_WHAT = "output folder"
    NAME = "files"

    def __init__(self, options: FilesSinkOptions, context: SinkContext | None = None) -> None:
        super().__init__(options, context)
        self._counters["files"] = 0

    # -- writing --------------------------------------------------------------------
    def output_paths(self, result: FusionResult) -> dict[str, Path]:
        """The files :meth:`write` would produce for ``result``, by kind.

        Keys are ``png16``/``pfm``/``npy`` (the enabled formats), and
        ``preview``, ``depth``, ``confidence`` / ``confidence_png``, ``points``, ``left_vpp``, ``right_vpp``
        when enabled (whether or not the result carries that data).

        Raises
        ------
        TypeError
            If ``result`` is not a FusionResult.
        ValueError
            A file name would not be safe or would leave ``dir`` (see :meth:`frame_stem`).
        """
        stem = self.frame_stem(result)
        names = {f: f"{stem}_disparity{_EXT[f]}" for f in self.options.formats}
        if self.options.preview:
            names["preview"] = f"{stem}_disparity_preview.png"
        if self.options.depth:
            names["depth"] = f"{stem}_depth.npy"
        if self.options.points:
            names["points"] = f"{stem}_points.ply"
        if self.options.confidence:
            names["confidence"] = f"{stem}_confidence.npy"
            names["confidence_png"] = f"{stem}_confidence.png"
        if self.options.painted:
            names["left_vpp"] = f"{stem}_left_vpp.png"
            names["right_vpp"] = f"{stem}_right_vpp.png"
        return {kind: path_inside(self._dir, name) for kind, name in names.items()}

    def write_one(self, result: FusionResult) -> None:
        """Write the files for one result (synchronously, each atomically; errors counted and logged)."""
        try:
            paths = self.output_paths(result)
        except ValueError as exc:  # an unsafe name: nothing is written, counted
            self._counters["errors"] += 1
            log.warning("files sink: not writing frame seq=%s: %s", result.frame.seq, exc)
            return
        failures = 0
        for kind, path in paths.items():
            try:
                writer = self._points_writer(result) if kind == "points" else self._writer(kind, result)
                if writer is None:
                    continue
                write_atomic(path, writer, self.options.overwrite)
                self._counters["files"] += 1
            except Exception as exc:  # noqa: BLE001 - counted, logged, never raised
                failures += 1
                log.warning("files sink: cannot write %s: %s", path, exc)
        self._counters["errors"] += failures
        if failures == 0:
            self._counters["written"] += 1

    def _writer(self, kind: str, result: FusionResult) -> Callable[[str], object] | None:  # noqa: PLR0911 - a branch per kind
        """A ``f(tmp_path)`` writing ``kind`` for ``result``, or None when absent."""
        if kind == "png16":
            data = encode_png16(result.disparity)
            return lambda p: Path(p).write_bytes(data)
        if kind == "pfm":
            d = _check_disparity(result.disparity)
            pfm = np.array(d, dtype=np.float32, copy=True)
            pfm[~np.isfinite(pfm)] = np.inf
            return lambda p: write_pfm(p, pfm)
        if kind == "preview":
            d = _check_disparity(result.disparity)
            top = self.options.preview_max_disparity
            rgb = colorize_disparity(d, 0.0, top) if top > 0 else colorize_disparity(d)
            return _png_writer(rgb, kind)
        if kind in ("confidence", "confidence_png"):
            return _confidence_writer(result.confidence, png=kind == "confidence_png")
        if kind in ("npy", "depth"):
            arr = result.disparity if kind == "npy" else result.depth
            if arr is None:
                return None
            if kind == "npy":
                _check_disparity(arr)
            buf = io.BytesIO()
            np.save(buf, _float_nan(arr), allow_pickle=False)
            data = buf.getvalue()
            return lambda p: Path(p).write_bytes(data)
        return _painted_writer(result.left_vpp if kind == "left_vpp" else result.right_vpp, kind)

    def _points_writer(self, result: FusionResult) -> Callable[[str], object] | None:
        """A ``f(tmp_path)`` writing the result's point cloud as PLY, or None without metric depth."""
        fr = result.frame
        if result.depth is None or fr.calib is None:
            return None
        stride = self.options.points_stride
        xyz, rgb = depth_to_points(np.asarray(result.depth), fr.left, fr.calib, stride=stride)
        c = fr.calib
        comments = [
            f"vpp-service rig {fr.rig} seq {int(fr.seq)} stamp_ns {int(fr.stamp_ns)}",
            f"rectified left camera: x right, y down, z forward, metres; stride {stride}",
            f"f {c.f:.9g} cx {'none' if c.cx is None else f'{c.cx:.9g}'} cy {'none' if c.cy is None else f'{c.cy:.9g}'}"
            f" baseline {c.baseline:.9g}",
        ]
        data = encode_ply(xyz, rgb, comments)
        return lambda p: Path(p).write_bytes(data)


def _confidence_writer(confidence: np.ndarray | None, png: bool) -> Callable[[str], object] | None:
    """A ``f(tmp_path)`` writing the confidence as 16-bit PNG (``png``) or float32 ``.npy``; None when absent."""
    if confidence is None:
        return None
    if png:
        data = encode_confidence_png16(confidence)
    else:
        buf = io.BytesIO()
        np.save(buf, np.asarray(confidence, np.float32), allow_pickle=False)
        data = buf.getvalue()
    return lambda p: Path(p).write_bytes(data)


def encode_confidence_png16(confidence: np.ndarray) -> bytes:
    """16-bit PNG of a confidence map: value = round(clip(confidence, 0, 1) * 65535) (NaN -> 0).

    Parameters
    ----------
    confidence : ndarray
        H x W float confidence in [0, 1].

    Returns
    -------
    bytes
        The PNG file; read back with ``cv2.imread(path, cv2.IMREAD_UNCHANGED) / 65535``.
    """
    c = np.asarray(confidence, np.float64)
    if c.ndim != 2:
        raise ValueError(f"confidence: must be an H x W map, got shape {c.shape}")
    q = np.rint(np.clip(np.nan_to_num(c, nan=0.0), 0.0, 1.0) * 65535.0).astype(np.uint16)
    ok, png = cv2.imencode(".png", q)
    if not ok:
        raise ValueError(f"confidence: OpenCV could not encode shape {c.shape}")
    return png.tobytes()


def _painted_writer(img: np.ndarray | None, kind: str) -> Callable[[str], object] | None:
    """A ``f(tmp_path)`` writing the painted image ``img`` as PNG, or None when absent."""
    if img is None:
        return None
    if not isinstance(img, np.ndarray) or img.dtype != np.uint8 or img.ndim not in (2, 3):
        raise ValueError(f"{kind}: must be an H x W (x C) uint8 image")
    return _png_writer(img, kind)


def _png_writer(img: np.ndarray, kind: str) -> Callable[[str], object]:
    """A ``f(tmp_path)`` writing the RGB (or grey) uint8 ``img`` as PNG."""
    bgr = img[..., ::-1] if img.ndim == 3 and img.shape[2] == 3 else img
    ok, png = cv2.imencode(".png", np.ascontiguousarray(bgr))
    if not ok:
        raise ValueError(f"{kind}: OpenCV could not encode shape {img.shape}")
    data = png.tobytes()
    return lambda p: Path(p).write_bytes(data)


__all__ = ["FORMATS", "FilesSink", "FilesSinkOptions", "decode_png16", "encode_confidence_png16", "encode_png16"]
