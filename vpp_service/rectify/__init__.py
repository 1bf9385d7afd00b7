"""Rectification of raw stereo frames from a calibration (``[rectify]``, ROS ``camera_info``).

- :mod:`.camera_info` -- one camera's ``K``, ``D``, ``R``, ``P`` (:class:`CameraInfo`), read from a
  ``camera_calibration`` YAML or an OpenCV FileStorage stereo calibration.
- :mod:`.stereo` -- :class:`StereoRectifier`: remap tables computed once, a raw frame in, the
  rectified frame (images, calibration from ``P``, sparse depth moved) out.
- :mod:`.options` -- the ``[rectify]`` config section (:class:`RectifyOptions`).
"""

from vpp_service.rectify.camera_info import (
    CalibrationError,
    CameraInfo,
    read_camera_info,
    read_opencv_stereo,
    write_camera_info,
)
from vpp_service.rectify.options import RectifyOptions
from vpp_service.rectify.stereo import StereoRectifier, check_pair

__all__ = [
    "CalibrationError",
    "CameraInfo",
    "RectifyOptions",
    "StereoRectifier",
    "check_pair",
    "read_camera_info",
    "read_opencv_stereo",
    "write_camera_info",
]
