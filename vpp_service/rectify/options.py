"""The ``[rectify]`` config section: which calibration rectifies the rig's raw frames.

Either two ROS camera_info YAMLs (``left`` + ``right``, as ``camera_calibration`` writes
them: the rectified image is exactly their ``P``), or one OpenCV FileStorage stereo
calibration (``opencv``: ``K1 D1 K2 D2 R T`` and the image size) rectified with
``cv2.stereoRectify`` at ``alpha``. The files are read and checked when the config is
validated, so a bad calibration is one line before anything starts (``run --check``
exits 2).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

from vpp_service.rectify.camera_info import CameraInfo, read_camera_info, read_opencv_stereo
from vpp_service.rectify.stereo import StereoRectifier, check_pair
from vpp_service.settings import Options, Range, reject


@dataclass(frozen=True)
class RectifyOptions(Options):
    """``[rectify]``: the rig's calibration.

    Attributes
    ----------
    left, right : str
        ROS camera_info YAML of each camera (``camera_calibration``'s ``left.yaml`` / ``right.yaml``).
    opencv : str
        OpenCV FileStorage stereo calibration instead (``K1``, ``D1``, ``K2``, ``D2``, ``R``, ``T``,
        ``imageSize`` or ``image_width`` + ``image_height``).
    alpha : float
        With ``opencv``: ``stereoRectify``'s free scaling in [0, 1]. 0 (default): every
        rectified pixel saw the scene (no black border; the raw image's rim is cut off);
        1: every raw pixel is kept (black borders).
    """

    left: str = ""
    right: str = ""
    opencv: str = ""
    alpha: Annotated[float, Range(0.0, 1.0)] = 0.0

    def cross_check(self) -> None:
        """One calibration (camera_info pair or OpenCV file), read and checked: a bad one fails the config."""
        if self.opencv and (self.left or self.right):
            raise reject("opencv", self.opencv, "'' when left and right are given (one calibration, not both)")
        if not self.opencv and not (self.left and self.right):
            missing = "left" if not self.left else "right"
            raise reject(missing, getattr(self, missing), "a camera_info YAML (or opencv: a FileStorage calibration)")
        check_pair(*self.cameras())  # reads and checks the files: a bad calibration fails the config

    def cameras(self) -> tuple[CameraInfo, CameraInfo]:
        """The two cameras, read from the files (raises CalibrationError)."""
        if self.opencv:
            return read_opencv_stereo(self.opencv, self.alpha)
        return read_camera_info(self.left), read_camera_info(self.right)

    def build(self) -> StereoRectifier:
        """The rectifier (its maps computed once)."""
        return StereoRectifier(*self.cameras())


__all__ = ["RectifyOptions"]
