"""One camera's calibration as ROS's ``sensor_msgs/CameraInfo`` holds it: ``K``, ``D``, ``R``, ``P``.

:class:`CameraInfo` is what :mod:`vpp_service.rectify` rectifies with, wherever it came
from: the YAML ``camera_calibration`` writes (:func:`read_camera_info`), an OpenCV
FileStorage stereo calibration run through ``stereoRectify`` (:func:`read_opencv_stereo`),
or a ``camera_info`` message (the ROS 2 source). Every constructor checks the numbers
(finite, a real pinhole ``K``, a ``P`` that projects) and raises :class:`CalibrationError`
with one line naming the problem.

The YAML layout (``camera_calibration``'s ``ost.yaml``)::

    image_width: 640
    image_height: 480
    camera_name: left
    camera_matrix: {rows: 3, cols: 3, data: [fx, 0, cx, 0, fy, cy, 0, 0, 1]}
    distortion_model: plumb_bob          # or rational_polynomial, equidistant
    distortion_coefficients: {rows: 1, cols: 5, data: [k1, k2, p1, p2, k3]}
    rectification_matrix: {rows: 3, cols: 3, data: [...]}
    projection_matrix: {rows: 3, cols: 4, data: [fx', 0, cx', Tx, 0, fy', cy', 0, 0, 0, 1, 0]}
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, cast

import numpy as np

#: Distortion models OpenCV can undo: ``plumb_bob`` (k1 k2 p1 p2 k3), ``rational_polynomial``
#: (8 coefficients), ``equidistant`` (fisheye, k1..k4).
DistortionModel = Literal["plumb_bob", "rational_polynomial", "equidistant"]
DISTORTION_MODELS: dict[str, tuple[int, ...]] = {
    "plumb_bob": (4, 5, 8),
    "rational_polynomial": (5, 8, 12, 14),
    "equidistant": (4,),
}
#: Largest image side a calibration may describe (a typo must not allocate giant maps).
MAX_SIDE = 16384


class CalibrationError(ValueError):
    """A calibration that cannot rectify: missing, non-finite or inconsistent numbers (one line)."""


@dataclass(frozen=True, eq=False)
class CameraInfo:
    """One camera of a stereo rig, as ``sensor_msgs/CameraInfo`` (and ``camera_calibration``) describes it.

    Attributes
    ----------
    width, height : int
        Image size the calibration is for (raw and rectified images have this size).
    k : ndarray
        3 x 3 intrinsics of the raw (distorted) camera.
    d : ndarray
        Distortion coefficients of ``distortion_model``.
    r : ndarray
        3 x 3 rotation from the raw camera to the rectified one.
    p : ndarray
        3 x 4 projection of the rectified camera; ``P[0, 3] = -fx' * baseline`` on the right camera.
    distortion_model : str
        One of :data:`DISTORTION_MODELS`.
    name : str
        Where it came from (a file, a topic): error messages name it.
    """

    width: int
    height: int
    k: np.ndarray
    d: np.ndarray
    r: np.ndarray
    p: np.ndarray
    distortion_model: DistortionModel = "plumb_bob"
    name: str = "camera_info"

    def __post_init__(self) -> None:
        n = self.name
        for attr, shape in (("k", (3, 3)), ("r", (3, 3)), ("p", (3, 4))):
            a = np.asarray(getattr(self, attr), dtype=np.float64)
            if a.size != shape[0] * shape[1]:
                raise CalibrationError(f"{n}: {attr.upper()} must hold {shape[0] * shape[1]} numbers, got {a.size}")
            a = a.reshape(shape)
            if not np.all(np.isfinite(a)):
                raise CalibrationError(f"{n}: {attr.upper()} holds a NaN or infinite value")
            object.__setattr__(self, attr, a)
        d = np.asarray(self.d, dtype=np.float64).ravel()
        if not np.all(np.isfinite(d)):
            raise CalibrationError(f"{n}: distortion coefficients hold a NaN or infinite value")
        if self.distortion_model not in DISTORTION_MODELS:
            raise CalibrationError(
                f"{n}: distortion_model {self.distortion_model!r} is not one of {', '.join(DISTORTION_MODELS)}"
            )
        sizes = DISTORTION_MODELS[self.distortion_model]
        if d.size == 0:
            d = np.zeros(sizes[0])
        if d.size not in sizes:
            raise CalibrationError(
                f"{n}: {self.distortion_model} takes {' or '.join(map(str, sizes))} coefficients, got {d.size}"
            )
        object.__setattr__(self, "d", d)
        for attr in ("width", "height"):
            v = getattr(self, attr)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not 1 <= int(v) <= MAX_SIDE:
                raise CalibrationError(f"{n}: image_{attr} must be an integer in [1, {MAX_SIDE}], got {v!r}")
            object.__setattr__(self, attr, int(v))
        k, p, r = self.k, self.p, self.r
        if not (k[0, 0] > 0 and k[1, 1] > 0 and k[2, 2] == 1 and not k[2, :2].any()):
            raise CalibrationError(f"{n}: K is not a camera matrix (fx={k[0, 0]}, fy={k[1, 1]}, K[2]={k[2].tolist()})")
        if not p.any():
            raise CalibrationError(f"{n}: P is all zeros (an uncalibrated camera_info)")
        if not (p[0, 0] > 0 and p[1, 1] > 0 and p[2, 2] == 1):
            raise CalibrationError(f"{n}: P does not project (fx'={p[0, 0]}, fy'={p[1, 1]}, P[2,2]={p[2, 2]})")
        if not np.allclose(r @ r.T, np.eye(3), atol=1e-4) or np.linalg.det(r) <= 0:
            raise CalibrationError(f"{n}: R is not a rotation matrix")


def _matrix(doc: dict[str, Any], key: str, name: str) -> list[float]:
    """``doc[key]["data"]`` of a ``camera_calibration`` YAML (a ``{rows, cols, data}`` mapping)."""
    m = doc.get(key)
    if not isinstance(m, dict) or "data" not in m:
        raise CalibrationError(f"{name}: {key} is missing (a mapping with rows, cols, data)")
    data = m["data"]
    if not isinstance(data, list) or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in data):
        raise CalibrationError(f"{name}: {key}.data must be a list of numbers")
    return [float(x) for x in data]


def read_camera_info(path: str | Path) -> CameraInfo:
    """Read a ROS camera_info YAML (as ``camera_calibration`` writes it).

    A missing ``rectification_matrix`` is the identity; a missing ``projection_matrix``
    is ``[K | 0]`` (a monocular calibration): a stereo pair needs both.

    Raises
    ------
    CalibrationError
        Unreadable file, a missing key, a non-finite or inconsistent value (names the file and key).
    """
    from ruamel.yaml import YAML, YAMLError

    p = Path(path)
    name = str(p)
    try:
        doc = YAML(typ="safe", pure=True).load(p.read_text(encoding="utf-8"))
    except OSError as exc:
        raise CalibrationError(f"{name}: cannot read: {exc.strerror or exc}") from None
    except (YAMLError, UnicodeDecodeError) as exc:
        raise CalibrationError(f"{name}: not a YAML file: {str(exc).splitlines()[0]}") from None
    if not isinstance(doc, dict):
        raise CalibrationError(f"{name}: not a camera_info YAML (a mapping with image_width, camera_matrix, ...)")
    for key in ("image_width", "image_height"):
        if key not in doc:
            raise CalibrationError(f"{name}: {key} is missing")
    k = _matrix(doc, "camera_matrix", name)
    d = _matrix(doc, "distortion_coefficients", name) if "distortion_coefficients" in doc else []
    r = _matrix(doc, "rectification_matrix", name) if "rectification_matrix" in doc else np.eye(3).ravel().tolist()
    if "projection_matrix" in doc:
        proj = _matrix(doc, "projection_matrix", name)
    else:
        km = np.asarray(k, dtype=np.float64).reshape(3, 3) if len(k) == 9 else np.zeros((3, 3))
        proj = np.hstack([km, np.zeros((3, 1))]).ravel().tolist()
    model = doc.get("distortion_model", "plumb_bob")
    return CameraInfo(
        width=doc["image_width"],
        height=doc["image_height"],
        k=np.asarray(k),
        d=np.asarray(d),
        r=np.asarray(r),
        p=np.asarray(proj),
        distortion_model=cast(DistortionModel, model),
        name=name,
    )


def write_camera_info(path: str | Path, info: CameraInfo, camera_name: str = "") -> None:
    """Write ``info`` as a ``camera_calibration`` YAML (what :func:`read_camera_info` reads)."""

    def mat(a: np.ndarray, rows: int, cols: int) -> str:
        return f"\n  rows: {rows}\n  cols: {cols}\n  data: [{', '.join(repr(float(x)) for x in a.ravel())}]"

    text = (
        f"image_width: {info.width}\nimage_height: {info.height}\ncamera_name: {camera_name or 'camera'}\n"
        f"camera_matrix:{mat(info.k, 3, 3)}\ndistortion_model: {info.distortion_model}\n"
        f"distortion_coefficients:{mat(info.d, 1, info.d.size)}\n"
        f"rectification_matrix:{mat(info.r, 3, 3)}\nprojection_matrix:{mat(info.p, 3, 4)}\n"
    )
    Path(path).write_text(text, encoding="utf-8")


def read_opencv_stereo(path: str | Path, alpha: float = 0.0) -> tuple[CameraInfo, CameraInfo]:
    """Read an OpenCV FileStorage stereo calibration and rectify it with ``cv2.stereoRectify``.

    The file holds ``K1``, ``D1``, ``K2``, ``D2`` (plumb_bob / rational_polynomial), ``R``, ``T``
    (right camera from left, as ``cv2.stereoCalibrate`` returns them; ``T`` in metres) and the
    image size as ``image_width`` + ``image_height`` or ``imageSize`` ``[w, h]``.

    Parameters
    ----------
    path : str or Path
        ``.yml`` / ``.yaml`` / ``.xml`` / ``.json`` FileStorage file.
    alpha : float
        ``stereoRectify``'s free scaling in [0, 1]: 0 (default) zooms in so that every
        rectified pixel is valid (no black border, some raw pixels lost); 1 keeps every
        raw pixel (black borders where no camera saw).

    Raises
    ------
    CalibrationError
        Unreadable file, a missing or non-finite matrix, an alpha outside [0, 1].
    """
    import cv2

    name = str(path)
    if not 0.0 <= alpha <= 1.0:
        raise CalibrationError(f"{name}: alpha must be in [0, 1], got {alpha}")
    if not Path(path).is_file():
        raise CalibrationError(f"{name}: no such file")
    try:
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    except cv2.error as exc:
        raise CalibrationError(f"{name}: not an OpenCV FileStorage file: {exc.err}") from None
    try:
        if not fs.isOpened():
            raise CalibrationError(f"{name}: not an OpenCV FileStorage file")

        def mat(key: str) -> np.ndarray:
            node = fs.getNode(key)
            m = None if node.empty() or not node.isMap() else node.mat()
            if m is None:
                raise CalibrationError(f"{name}: {key} is missing (a matrix)")
            a = np.asarray(m, dtype=np.float64)
            if not np.all(np.isfinite(a)):
                raise CalibrationError(f"{name}: {key} holds a NaN or infinite value")
            return a

        k1, d1, k2, d2, rot, t = (mat(k) for k in ("K1", "D1", "K2", "D2", "R", "T"))
        size_node = fs.getNode("imageSize")
        if not size_node.empty():
            sm = size_node.mat()
            size = np.asarray(sm if sm is not None else [size_node.at(i).real() for i in range(2)]).ravel()
            w, h = int(size[0]), int(size[1])
        else:
            wn, hn = fs.getNode("image_width"), fs.getNode("image_height")
            if wn.empty() or hn.empty():
                raise CalibrationError(f"{name}: image size is missing (imageSize, or image_width + image_height)")
            w, h = int(wn.real()), int(hn.real())
    finally:
        fs.release()
    if not (1 <= w <= MAX_SIDE and 1 <= h <= MAX_SIDE):
        raise CalibrationError(f"{name}: image size {w}x{h} is out of range")
    if rot.size != 9 or t.size != 3:
        raise CalibrationError(f"{name}: R must be 3 x 3 and T 3 x 1")
    model: DistortionModel = "plumb_bob" if d1.size <= 5 else "rational_polynomial"
    try:
        r1, r2, p1, p2, *_ = cv2.stereoRectify(
            k1, d1, k2, d2, (w, h), rot.reshape(3, 3), t.reshape(3, 1), flags=cv2.CALIB_ZERO_DISPARITY, alpha=alpha
        )
    except cv2.error as exc:
        raise CalibrationError(f"{name}: stereoRectify failed: {exc.err}") from None
    left = CameraInfo(w, h, k1, d1, r1, p1, model, name=f"{name} (left)")
    right = CameraInfo(w, h, k2, d2, r2, p2, model, name=f"{name} (right)")
    return left, right


__all__ = [
    "DISTORTION_MODELS",
    "CalibrationError",
    "CameraInfo",
    "DistortionModel",
    "read_camera_info",
    "read_opencv_stereo",
    "write_camera_info",
]
