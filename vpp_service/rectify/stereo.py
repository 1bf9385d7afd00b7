"""Stereo rectification of raw frames: undistort and rotate both views into the calibration's ``P``.

:class:`StereoRectifier` is built once per calibration (two :class:`CameraInfo`): it checks
that they are a rectified pair (same size, same ``fx'``, ``fy'``, ``cy'``, a right ``P``
with a positive baseline) and computes the remap tables with
``cv2.initUndistortRectifyMap`` (``cv2.fisheye`` for ``equidistant``) in OpenCV's
fixed-point form (``CV_16SC2`` + interpolation table: the fastest ``remap``). Calling it on
a raw :class:`~vpp_service.frame.StereoFrame` returns the rectified frame, as
``stereo_image_proc`` does:

* **Images.** Both views are remapped (bilinear) into exactly ``P``'s image: the
  outputs line up with the calibration's rectified left camera.
* **Calibration.** ``f = P_left[0, 0]``, ``baseline = -P_right[0, 3] / P_right[0, 0]``,
  ``doffs = cx'_right - cx'_left``, ``cx``/``cy`` of ``P_left``
  (:meth:`StereoRectifier.calibration`); a frame's own ``calib`` is not needed.
* **Sparse depth** given with a raw frame (``sensor_depth``, ``sparse_disparity``) is
  registered to the raw left image: each point moves to its rectified pixel (its depth
  along the rectified axis; a disparity keeps its value), the nearest wins a pixel.
* **Ground truth** (``gt_disparity``, ``nocc_mask``) is taken as given: it describes the
  output, which lives in the rectified left frame.
* A frame with ``meta["rectified"] = True`` is already rectified: only a missing ``calib``
  is filled in.

A frame whose size differs from the calibration's raises ``ValueError`` (the pipeline
counts it as rejected and goes on). ``meta["timing_ms"]["rectify"]`` records the cost.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from vpp_service.frame import Calibration, StereoFrame
from vpp_service.rectify.camera_info import CalibrationError, CameraInfo

#: Relative tolerance on the numbers the two rectified cameras must share.
_REL_TOL = 1e-6


@dataclass(frozen=True)
class _Maps:
    """One view's remap tables (fixed point: ``map1`` CV_16SC2, ``map2`` CV_16UC1)."""

    map1: np.ndarray
    map2: np.ndarray


def _maps(info: CameraInfo) -> _Maps:
    import cv2

    size = (info.width, info.height)
    if info.distortion_model == "equidistant":
        m1, m2 = cv2.fisheye.initUndistortRectifyMap(info.k, info.d, info.r, info.p, size, cv2.CV_16SC2)
    else:
        m1, m2 = cv2.initUndistortRectifyMap(info.k, info.d, info.r, info.p, size, cv2.CV_16SC2)
    return _Maps(m1, m2)


def check_pair(left: CameraInfo, right: CameraInfo) -> Calibration:
    """The rectified stereo calibration of a pair of camera_info; raises if they are not a pair.

    Raises
    ------
    CalibrationError
        Sizes differ, ``fx'``/``fy'``/``cy'`` of the two ``P`` differ, the left ``P`` has a
        translation, or the baseline ``-P_right[0, 3] / fx'`` is not > 0.
    """
    where = f"{left.name} / {right.name}"
    if (left.width, left.height) != (right.width, right.height):
        raise CalibrationError(
            f"{where}: image sizes differ ({left.width}x{left.height} vs {right.width}x{right.height})"
        )
    pl, pr = left.p, right.p
    for (i, j), what in (((0, 0), "fx'"), ((1, 1), "fy'"), ((1, 2), "cy'")):
        if abs(pl[i, j] - pr[i, j]) > _REL_TOL * max(1.0, abs(pl[i, j])):
            raise CalibrationError(f"{where}: not a rectified pair: P {what} differs ({pl[i, j]:g} vs {pr[i, j]:g})")
    f = float(pl[0, 0])
    if abs(pl[0, 3]) > _REL_TOL * f or abs(pl[1, 3]) > _REL_TOL * f:
        raise CalibrationError(
            f"{where}: the left P must have no translation (P[0,3]={pl[0, 3]:g}; are left and right swapped?)"
        )
    baseline = -float(pr[0, 3]) / f
    if not baseline > 0:
        raise CalibrationError(
            f"{where}: baseline -P_right[0,3]/fx' = {baseline:g} must be > 0 (are left and right swapped?)"
        )
    return Calibration(f=f, baseline=baseline, doffs=float(pr[0, 2] - pl[0, 2]), cx=float(pl[0, 2]), cy=float(pl[1, 2]))


class StereoRectifier:
    """Rectify raw stereo frames with one calibration (see the module docstring).

    Parameters
    ----------
    left, right : CameraInfo
        The two cameras (``K``, ``D``, ``R``, ``P``).

    Raises
    ------
    CalibrationError
        The two are not a rectified pair (:func:`check_pair`).
    """

    def __init__(self, left: CameraInfo, right: CameraInfo) -> None:
        self.left, self.right = left, right
        self.calib = check_pair(left, right)
        self.size = (left.height, left.width)
        self._maps = (_maps(left), _maps(right))

    @property
    def calibration(self) -> Calibration:
        """The rectified stereo calibration (from the two ``P``)."""
        return self.calib

    def remap(self, image: np.ndarray, view: int) -> np.ndarray:
        """Rectify one raw image (``view`` 0 = left, 1 = right), bilinear; outside the raw image is 0."""
        import cv2

        m = self._maps[view]
        out = cv2.remap(image, m.map1, m.map2, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
        if out.ndim < image.ndim:  # an H x W x 1 image comes back H x W
            out = out.reshape(*out.shape, 1)
        return out

    def rectify_points(self, uv: np.ndarray, view: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Raw pixel positions (N x 2) -> rectified positions (N x 2) and each ray's ``z`` factor.

        The factor is the rectified depth of a point at raw depth 1 along that ray
        (``(R @ [x, y, 1])_z`` of its undistorted normalised coordinates ``x, y``).
        """
        import cv2

        info = self.left if view == 0 else self.right
        pts = np.ascontiguousarray(uv, dtype=np.float64).reshape(-1, 1, 2)
        if info.distortion_model == "equidistant":
            norm = cv2.fisheye.undistortPoints(pts, info.k, info.d)
        else:
            norm = cv2.undistortPoints(pts, info.k, info.d)
        xy1 = np.concatenate([norm.reshape(-1, 2), np.ones((len(uv), 1))], axis=1)
        rays = xy1 @ info.r.T  # rectified camera coordinates at raw depth 1
        z = rays[:, 2]
        proj = rays @ info.p[:, :3].T
        with np.errstate(divide="ignore", invalid="ignore"):
            out = proj[:, :2] / proj[:, 2:3]
        return out, z

    def _move_sparse(self, values: np.ndarray, metric: bool) -> np.ndarray:
        """A raw-registered sparse map -> the rectified left frame (nearest point wins a pixel)."""
        h, w = self.size
        v, u = np.nonzero(np.isfinite(values) & (values > 0))
        out = np.full((h, w), np.nan if not metric else 0.0, dtype=np.float32)
        if len(u) == 0:
            return out
        vals = values[v, u].astype(np.float64)
        xy, z = self.rectify_points(np.stack([u, v], axis=1).astype(np.float64))
        if metric:
            vals = vals * z
        x, y = np.rint(xy[:, 0]), np.rint(xy[:, 1])
        ok = np.isfinite(x) & np.isfinite(y) & (x >= 0) & (x < w) & (y >= 0) & (y < h) & (vals > 0)
        x, y, vals = x[ok].astype(np.intp), y[ok].astype(np.intp), vals[ok]
        # nearest wins: write far-to-near for depth (small last), small-to-large for disparity
        order = np.argsort(-vals) if metric else np.argsort(vals)
        out[y[order], x[order]] = vals[order]
        return out

    def __call__(self, frame: StereoFrame) -> StereoFrame:
        """The rectified frame (see the module docstring).

        Raises
        ------
        ValueError
            The frame's size is not the calibration's.
        """
        t0 = time.perf_counter()
        if frame.meta.get("rectified") is True:
            return frame if frame.calib is not None else frame.with_(calib=self.calib)
        h, w = self.size
        if frame.left.shape[:2] != (h, w) or frame.right.shape[:2] != (h, w):
            got = f"{frame.left.shape[1]}x{frame.left.shape[0]}"
            raise ValueError(f"raw frame is {got}, the [rectify] calibration is for {w}x{h}")
        sensor = None if frame.sensor_depth is None else self._move_sparse(frame.sensor_depth, metric=True)
        sparse = None if frame.sparse_disparity is None else self._move_sparse(frame.sparse_disparity, metric=False)
        meta = dict(frame.meta)
        out = frame.with_(
            left=self.remap(frame.left, 0),
            right=self.remap(frame.right, 1),
            calib=self.calib,
            sensor_depth=sensor,
            sparse_disparity=sparse,
            meta=meta,
        )
        meta["timing_ms"] = {**meta.get("timing_ms", {}), "rectify": (time.perf_counter() - t0) * 1e3}
        return out


__all__ = ["StereoRectifier", "check_pair"]
