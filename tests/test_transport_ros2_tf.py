"""StaticTransforms: the chain between two frames through their common ancestor, as tf2 composes it."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.ros2_robot import tf_message
from vpp_service.transport.ros2.messages import tf_transforms
from vpp_service.transport.ros2.tf import StaticTransforms

#: ROS body -> optical rotation (x right = -y_body, y down = -z_body, z forward = x_body) as (x, y, z, w).
OPTICAL = (-0.5, 0.5, -0.5, 0.5)
IDENTITY = (0.0, 0.0, 0.0, 1.0)


def tree(*entries) -> StaticTransforms:
    t = StaticTransforms()
    t.add(tf_transforms(tf_message(list(entries))))
    return t


def robot() -> StaticTransforms:
    """base_link -> camera_link (0.2, 0.06, 0.5) -> left_optical (optical rotation); base_link -> velodyne (0, 0, 1)."""
    return tree(
        ("base_link", "camera_link", (0.2, 0.06, 0.5), IDENTITY),
        ("camera_link", "left_optical", (0.0, 0.0, 0.0), OPTICAL),
        ("base_link", "velodyne", (0.0, 0.0, 1.0), IDENTITY),
    )


def test_chain_through_the_common_ancestor():
    # a return 5 m ahead of the LiDAR, 0.5 m below it: (5, 0, -0.5) in velodyne -> (5, 0, 0.5) in base_link
    # -> (4.8, -0.06, 0) from the camera, body axes -> optical (x = -y, y = -z, z = x) = (0.06, 0, 4.8)
    m = robot().lookup("left_optical", "velodyne")
    np.testing.assert_allclose(m @ [5.0, 0.0, -0.5, 1.0], [0.06, 0.0, 4.8, 1.0], atol=1e-12)
    np.testing.assert_allclose(m[3], [0, 0, 0, 1])
    # the other way round is its inverse, and a frame to itself is the identity
    np.testing.assert_allclose(robot().lookup("velodyne", "left_optical") @ m, np.eye(4), atol=1e-12)
    np.testing.assert_allclose(robot().lookup("/velodyne", "velodyne"), np.eye(4))


def test_later_transform_replaces_the_child():
    t = robot()
    t.add(tf_transforms(tf_message([("base_link", "velodyne", (0.0, 0.0, 2.0), IDENTITY)])))
    np.testing.assert_allclose(t.lookup("base_link", "velodyne")[:3, 3], [0, 0, 2.0])


def test_unconnected_frames_and_loops():
    t = robot()
    t.add(tf_transforms(tf_message([("odom", "map_lidar", (0.0, 0.0, 0.0), IDENTITY)])))
    with pytest.raises(LookupError, match="no static transform chain from 'map_lidar' to 'left_optical'"):
        t.lookup("left_optical", "map_lidar")
    loop = tree(("a", "b", (0.0, 0.0, 0.0), IDENTITY), ("b", "a", (0.0, 0.0, 0.0), IDENTITY))
    with pytest.raises(LookupError, match="loop"):
        loop.lookup("a", "c")
