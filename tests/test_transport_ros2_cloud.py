"""Point cloud -> sparse depth in the left camera: extrinsic, projection with P, counted drops, nearest wins."""

from __future__ import annotations

import numpy as np
import pytest

from vpp_service.transport.ros2.cloud import check_extrinsic, cloud_to_depth

P = np.array([[100.0, 0, 4.0, 0], [0, 100.0, 3.0, 0], [0, 0, 1, 0]])


def test_projection_counts_and_nearest_wins():
    xyz = np.array(
        [
            [0.0, 0.0, 2.0],  # centre pixel (3, 4)
            [0.0, 0.0, 1.0],  # same pixel, nearer: wins
            [0.01, 0.02, 1.0],  # u = 4 + 1, v = 3 + 2
            [0.0, 0.0, -1.0],  # behind
            [1.0, 0.0, 1.0],  # u = 104: outside
            [np.nan, 0.0, 1.0],  # not finite
        ]
    )
    depth, counts = cloud_to_depth(xyz, np.eye(4), P, (6, 8))
    assert (counts.used, counts.behind, counts.outside, counts.nonfinite) == (3, 1, 1, 1)
    assert depth[3, 4] == 1.0 and depth[5, 5] == 1.0
    assert np.isfinite(depth).sum() == 2


def test_extrinsic_applied():
    # lidar x forward, y left, z up -> camera z forward, x right, y down; lidar 0.5 m behind the camera
    r = np.array([[0, -1, 0], [0, 0, -1], [1, 0, 0]], float)
    t = np.eye(4)
    t[:3, :3] = r
    t[:3, 3] = [0, 0, -0.5]
    depth, counts = cloud_to_depth(np.array([[2.5, 0.0, 0.0]]), t, P, (6, 8))
    assert counts.used == 1 and depth[3, 4] == pytest.approx(2.0)


def test_empty_cloud():
    depth, counts = cloud_to_depth(np.zeros((0, 3)), np.eye(4), P, (2, 2))
    assert counts.used == 0 and np.isnan(depth).all()


@pytest.mark.parametrize("bad", [np.eye(3), np.full((4, 4), np.nan), np.ones((4, 4))])
def test_bad_extrinsic(bad):
    with pytest.raises(ValueError, match="extrinsic"):
        check_extrinsic(bad)
