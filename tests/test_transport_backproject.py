"""The one back-projection of every points output: geometry, stride, valid pixels, colours, bad options."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.points import CALIB, assert_cloud_is_depth, clipped_result
from vpp_service.frame import Calibration
from vpp_service.transport.backproject import DEFAULT_STRIDE, MAX_STRIDE, check_stride, depth_to_points


def test_points_by_hand():
    """With f = 2, cx = 1, cy = 0.5 pixel (v, u) at depth z is ((u - 1) z / 2, (v - 0.5) z / 2, z)."""
    depth = np.array([[2.0, np.nan, 4.0], [0.0, 1.0, np.inf]], np.float32)
    image = np.array([[10, 20, 30], [40, 50, 60]], np.uint8)
    xyz, rgb = depth_to_points(depth, image, Calibration(f=2.0, baseline=0.1, cx=1.0, cy=0.5))
    np.testing.assert_array_equal(xyz, [[-1.0, -0.5, 2.0], [2.0, -1.0, 4.0], [0.0, 0.25, 1.0]])
    np.testing.assert_array_equal(rgb, [[10] * 3, [30] * 3, [50] * 3])  # grey replicated into RGB


def test_principal_point_defaults_to_the_image_centre():
    depth = np.full((3, 5), 2.0, np.float32)
    xyz, _ = depth_to_points(depth, None, Calibration(f=4.0, baseline=0.1))
    assert xyz[0].tolist() == [(0 - 2.0) * 2.0 / 4.0, (0 - 1.0) * 2.0 / 4.0, 2.0]
    assert xyz[-1].tolist() == [1.0, 0.5, 2.0]


def test_no_image_gives_grey():
    _, rgb = depth_to_points(np.ones((2, 2), np.float32), None, Calibration(f=1.0, baseline=0.1))
    assert rgb.shape == (4, 3) and np.all(rgb == 128)


@pytest.mark.parametrize("stride", [1, 2, 3, DEFAULT_STRIDE, 7])
def test_a_clipped_depth_map_as_points(stride):
    """On a real fused result: exactly the valid pixels of the stride grid, each on its pixel, inside the clip."""
    res = clipped_result()
    xyz, rgb = depth_to_points(res.depth, res.frame.left, CALIB, stride=stride)
    assert_cloud_is_depth(xyz, rgb, res, stride)


def test_organized_keeps_every_grid_pixel():
    res = clipped_result()
    xyz, rgb = depth_to_points(res.depth, res.frame.left, CALIB, stride=2, organized=True)
    grid = res.depth[::2, ::2]
    assert len(xyz) == grid.size
    np.testing.assert_array_equal(np.isnan(xyz[:, 2]), ~np.isfinite(grid).reshape(-1))
    np.testing.assert_array_equal(rgb, res.frame.left[::2, ::2].reshape(-1, 3))  # invalid pixels keep their colour
    valid_xyz, _ = depth_to_points(res.depth, res.frame.left, CALIB, stride=2)
    np.testing.assert_array_equal(xyz[np.isfinite(xyz[:, 2])], valid_xyz)


@pytest.mark.parametrize("bad", [0, -1, MAX_STRIDE + 1, 2.5, True, "4", None])
def test_bad_stride_is_refused_naming_the_key(bad):
    with pytest.raises(ValueError, match=r"points_stride: must be an integer in \[1, 64\]"):
        check_stride(bad)


def test_bad_inputs():
    calib = Calibration(f=1.0, baseline=0.1)
    with pytest.raises(ValueError, match="H x W"):
        depth_to_points(np.ones((2, 2, 1), np.float32), None, calib)
    with pytest.raises(ValueError, match="differ in size"):
        depth_to_points(np.ones((2, 2), np.float32), np.zeros((3, 2), np.uint8), calib)
    with pytest.raises(ValueError, match="stride"):
        depth_to_points(np.ones((2, 2), np.float32), None, calib, stride=0)
