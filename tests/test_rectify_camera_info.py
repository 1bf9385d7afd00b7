"""camera_info YAML and OpenCV FileStorage calibrations: read, written back, bad ones named in one line."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from helpers.raw_rig import rig_calibration
from vpp_service.rectify import CalibrationError, CameraInfo, read_camera_info, read_opencv_stereo, write_camera_info

#: A camera_info YAML as ROS's camera_calibration writes it (a real one's layout, numbers of a 640x480 camera).
ROS_YAML = """image_width: 640
image_height: 480
camera_name: narrow_stereo/left
camera_matrix:
  rows: 3
  cols: 3
  data: [430.2, 0, 306.7, 0, 430.8, 237.1, 0, 0, 1]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [-0.12, 0.031, 0.0004, -0.0002, 0]
rectification_matrix:
  rows: 3
  cols: 3
  data: [0.9999, -0.0021, 0.0137, 0.0021, 1.0, 0.0003, -0.0137, -0.0003, 0.9999]
projection_matrix:
  rows: 3
  cols: 4
  data: [412.5, 0, 311.2, 0, 0, 412.5, 240.3, 0, 0, 0, 1, 0]
"""


def test_reads_a_camera_calibration_yaml(tmp_path):
    path = tmp_path / "left.yaml"
    path.write_text(ROS_YAML)
    info = read_camera_info(path)
    assert (info.width, info.height, info.distortion_model) == (640, 480, "plumb_bob")
    assert info.k[0, 0] == 430.2 and info.k[1, 2] == 237.1
    assert info.d.tolist() == [-0.12, 0.031, 0.0004, -0.0002, 0.0]
    assert info.p.shape == (3, 4) and info.p[0, 0] == 412.5 and info.p[1, 2] == 240.3


def test_write_then_read_gives_the_same_camera(tmp_path):
    left, _ = rig_calibration(320, 240)
    write_camera_info(tmp_path / "l.yaml", left, "left")
    back = read_camera_info(tmp_path / "l.yaml")
    for attr in ("k", "d", "r", "p"):
        np.testing.assert_array_equal(getattr(back, attr), getattr(left, attr))
    assert (back.width, back.height) == (320, 240)


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda s: s.replace("430.2", ".nan"), "K holds a NaN"),
        (
            lambda s: s.replace(
                "412.5, 0, 311.2, 0, 0, 412.5, 240.3, 0, 0, 0, 1, 0", "0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0"
            ),
            "P is all zeros",
        ),
        (
            lambda s: s.replace("-0.12, 0.031, 0.0004, -0.0002, 0", "-0.12, 0.031, 0.0004"),
            "plumb_bob takes 4 or 5 or 8",
        ),
        (lambda s: s.replace("plumb_bob", "kannala"), "distortion_model 'kannala'"),
        (lambda s: s.replace("image_width: 640\n", ""), "image_width is missing"),
        (lambda s: s.replace("image_width: 640", "image_width: 0"), "image_width must be an integer"),
        (lambda s: s.replace("0.9999, -0.0021", "1.9999, -0.0021"), "R is not a rotation"),
        (lambda s: "[1, 2", "not a YAML file"),
    ],
)
def test_a_bad_yaml_is_one_line_naming_the_file(tmp_path, edit, message):
    path = tmp_path / "bad.yaml"
    path.write_text(edit(ROS_YAML))
    with pytest.raises(CalibrationError, match=message) as info:
        read_camera_info(path)
    assert "\n" not in str(info.value) and str(path) in str(info.value)


def test_a_missing_file_is_named(tmp_path):
    with pytest.raises(CalibrationError, match="cannot read"):
        read_camera_info(tmp_path / "none.yaml")


def _opencv_file(path, t=(-0.12, 0.0, 0.0), d1=(-0.1, 0.02, 0, 0, 0)):
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    k = np.array([[400.0, 0, 319.5], [0, 400.0, 239.5], [0, 0, 1]])
    fs.write("K1", k)
    fs.write("D1", np.array([d1], dtype=np.float64))
    fs.write("K2", k + np.array([[3.0, 0, 2], [0, 3, -1], [0, 0, 0]]))
    fs.write("D2", np.array([[-0.09, 0.015, 0, 0, 0]]))
    fs.write("R", cv2.Rodrigues(np.deg2rad([0.3, -0.5, 0.2]))[0])
    fs.write("T", np.array([t], dtype=np.float64).T)
    fs.write("image_width", 640)
    fs.write("image_height", 480)
    fs.release()


@pytest.mark.parametrize("alpha", [0.0, 1.0])
def test_opencv_stereo_calibration_is_rectified_with_alpha(tmp_path, alpha):
    _opencv_file(tmp_path / "stereo.yml")
    left, right = read_opencv_stereo(tmp_path / "stereo.yml", alpha)
    # a rectified pair: same fx', a right P with the baseline |T| (metres), rows aligned
    assert left.p[0, 0] == pytest.approx(right.p[0, 0])
    assert -right.p[0, 3] / right.p[0, 0] == pytest.approx(0.12, rel=1e-6)
    assert left.p[1, 2] == pytest.approx(right.p[1, 2])
    assert (left.width, left.height) == (640, 480)


def test_opencv_alpha_zoom_differs(tmp_path):
    _opencv_file(tmp_path / "stereo.yml")
    f0 = read_opencv_stereo(tmp_path / "stereo.yml", 0.0)[0].p[0, 0]
    f1 = read_opencv_stereo(tmp_path / "stereo.yml", 1.0)[0].p[0, 0]
    assert f0 > f1  # alpha 0 zooms in (no border), alpha 1 keeps every raw pixel


def test_opencv_nan_and_missing_are_named(tmp_path):
    _opencv_file(tmp_path / "nan.yml", d1=(float("nan"), 0, 0, 0, 0))
    with pytest.raises(CalibrationError, match="D1 holds a NaN"):
        read_opencv_stereo(tmp_path / "nan.yml")
    (tmp_path / "empty.yml").write_text("%YAML:1.0\n---\nK1: 1\n")
    with pytest.raises(CalibrationError, match="is missing"):
        read_opencv_stereo(tmp_path / "empty.yml")
    with pytest.raises(CalibrationError, match="alpha"):
        read_opencv_stereo(tmp_path / "nan.yml", 1.5)


def test_camera_info_checks_its_matrices():
    left, _ = rig_calibration(64, 48)
    with pytest.raises(CalibrationError, match="P does not project"):
        CameraInfo(64, 48, left.k, left.d, left.r, -left.p)
    with pytest.raises(CalibrationError, match="K is not a camera matrix"):
        CameraInfo(64, 48, np.zeros((3, 3)), left.d, left.r, left.p)
