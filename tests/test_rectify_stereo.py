"""StereoRectifier: raw images back to the calibration's P, calibration from P, sparse points moved, bad input."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from helpers.raw_rig import raw_image, rig_calibration
from helpers.shared_data import need_shared
from vpp_service.datasets import open_dataset
from vpp_service.frame import Calibration, StereoFrame
from vpp_service.rectify import CalibrationError, CameraInfo, StereoRectifier, check_pair


@pytest.fixture(scope="module")
def scene() -> StereoFrame:
    root = need_shared("middlebury2005_2006_thirdsize")
    return open_dataset("middlebury2006", root).select(["Art"])[0]


def test_calibration_comes_from_p():
    left, right = rig_calibration(300, 200, f=420.0, baseline=0.16)
    c = StereoRectifier(left, right).calibration
    assert (c.f, c.doffs, c.cx, c.cy) == (420.0, 0.0, 149.5, 99.5) and c.baseline == pytest.approx(0.16)


def test_rectifies_a_raw_pair_back_to_the_rectified_images(scene):
    h, w = scene.shape
    left, right = rig_calibration(w, h)
    raw = scene.with_(left=raw_image(scene.left, left), right=raw_image(scene.right, right), calib=None)
    out = StereoRectifier(left, right)(raw)
    assert out.left.shape == scene.left.shape and out.left.dtype == np.uint8
    m = 12  # the synthesis lost the rim (raw pixels beyond the rectified image)
    for got, want in ((out.left, scene.left), (out.right, scene.right)):
        err = np.abs(got[m:-m, m:-m].astype(np.int16) - want[m:-m, m:-m].astype(np.int16))
        raw_err = np.abs(raw.left[m:-m, m:-m].astype(np.int16) - want[m:-m, m:-m].astype(np.int16))
        assert np.median(err) <= 3 and err.mean() < 0.25 * raw_err.mean()  # two bilinear passes of blur only
    assert out.calib is not None and out.calib.f == left.p[0, 0]
    assert out.meta["timing_ms"]["rectify"] > 0
    assert out.gt_disparity is scene.gt_disparity  # ground truth describes the rectified output


def test_sparse_depth_moves_to_its_rectified_pixel():
    w, h = 320, 240
    left, right = rig_calibration(w, h)
    rect = StereoRectifier(left, right)
    rng = np.random.default_rng(3)
    # 3-D points in the rectified left camera, seen by the raw left camera (rotated by R^T, then distorted)
    xy = np.stack([rng.uniform(30, w - 30, 200), rng.uniform(30, h - 30, 200)], axis=1)
    z = rng.uniform(1.0, 6.0, 200)
    p = left.p[:, :3]
    pts = np.linalg.solve(p, np.stack([xy[:, 0], xy[:, 1], np.ones(200)])).T * z[:, None]
    raw_pts = pts @ left.r  # R^T X as row vectors: raw camera coordinates
    uv, _ = cv2.projectPoints(raw_pts, np.zeros(3), np.zeros(3), left.k, left.d)
    uv = np.rint(uv.reshape(-1, 2)).astype(int)
    depth = np.zeros((h, w), np.float32)
    depth[uv[:, 1], uv[:, 0]] = raw_pts[:, 2]
    frame = StereoFrame(np.zeros((h, w), np.uint8), np.zeros((h, w), np.uint8), sensor_depth=depth)
    out = rect(frame)
    assert out.sensor_depth is not None
    got_v, got_u = np.nonzero(out.sensor_depth > 0)
    assert len(got_u) >= 195  # a few may collide on one pixel
    # every moved point lies within a pixel (the raw rounding) of a true rectified point, with its true depth
    for u, v in zip(got_u, got_v, strict=True):
        d2 = (xy[:, 0] - u) ** 2 + (xy[:, 1] - v) ** 2
        i = int(np.argmin(d2))
        assert d2[i] < 1.5**2
        assert out.sensor_depth[v, u] == pytest.approx(z[i], rel=0.01)


def test_a_wrong_size_frame_is_refused_naming_both_sizes():
    left, right = rig_calibration(320, 240)
    frame = StereoFrame(np.zeros((200, 300), np.uint8), np.zeros((200, 300), np.uint8))
    with pytest.raises(ValueError, match="raw frame is 300x200, the \\[rectify\\] calibration is for 320x240"):
        StereoRectifier(left, right)(frame)


def test_a_frame_marked_rectified_is_not_remapped():
    left, right = rig_calibration(64, 48)
    img = np.arange(64 * 48, dtype=np.uint32).astype(np.uint8).reshape(48, 64)
    frame = StereoFrame(img, img, meta={"rectified": True})
    out = StereoRectifier(left, right)(frame)
    assert out.left is img and out.calib == check_pair(left, right)
    own = Calibration(f=100.0, baseline=0.1)
    assert StereoRectifier(left, right)(frame.with_(calib=own)).calib is own


def test_swapped_or_mismatched_cameras_are_refused():
    left, right = rig_calibration(64, 48)
    with pytest.raises(CalibrationError, match=r"left P must have no translation .* are left and right swapped"):
        StereoRectifier(right, left)
    p = right.p.copy()
    p[0, 3] = -p[0, 3]
    behind = CameraInfo(64, 48, right.k, right.d, right.r, p, name="right")
    with pytest.raises(CalibrationError, match=r"baseline .* must be > 0"):
        check_pair(left, behind)
    p = right.p.copy()
    p[0, 0] += 5
    other = CameraInfo(64, 48, right.k, right.d, right.r, p, name="right")
    with pytest.raises(CalibrationError, match="not a rectified pair: P fx' differs"):
        check_pair(left, other)
    small = CameraInfo(32, 48, right.k, right.d, right.r, right.p, name="right")
    with pytest.raises(CalibrationError, match="image sizes differ"):
        check_pair(left, small)
