"""``vpp-service run`` flags for ROS 2: --source/--sink ros2, --ros-namespace, --ros-domain, --rosbag."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.ros2_robot import StereoRig, write_bag
from vpp_service.cli import build_parser
from vpp_service.cli.run import overrides_from_args
from vpp_service.service.config import DEFAULT_CONFIG, validate_config
from vpp_service.settings import SettingsError


def config(argv: list[str]):
    args = build_parser().parse_args(["run", *argv])
    return validate_config(overrides_from_args(DEFAULT_CONFIG, args))


def test_ros_namespace_and_domain_reach_source_and_sinks():
    cfg = config(
        ["--source", "ros2", "--sink", "ros2", "--sink", "zenoh", "--ros-namespace", "/r", "--ros-domain", "5"]
    )
    assert cfg.source.name == "ros2" and cfg.source.options.namespace == "/r" and cfg.source.options.domain_id == 5
    ros_sink = next(s for s in cfg.sinks if s.name == "ros2")
    assert ros_sink.options.namespace == "/r" and ros_sink.options.domain_id == 5
    assert "namespace" not in next(s for s in cfg.sinks if s.name == "zenoh").raw


def test_bad_ros_flags_rejected():
    with pytest.raises(SettingsError, match="domain_id"):
        config(["--source", "ros2", "--ros-domain", "999"])
    with pytest.raises(SettingsError, match="namespace"):
        config(["--sink", "ros2", "--ros-namespace", "no/slash"])


def test_rosbag_flag(tmp_path):
    img = np.zeros((4, 6, 3), np.uint8)
    write_bag(str(tmp_path / "bag"), "mcap", StereoRig(img, img, 10.0, 0.1, 2.5, 2.5, 1.5, np.zeros((0, 3))), [1])
    cfg = config(["--rosbag", str(tmp_path / "bag"), "--ros-namespace", "/cam"])
    assert cfg.source.name == "rosbag2" and cfg.source.options.path == str(tmp_path / "bag")
    assert cfg.source.options.namespace == "/cam"
    with pytest.raises(SettingsError, match="path"):
        config(["--rosbag", str(tmp_path / "missing")])
