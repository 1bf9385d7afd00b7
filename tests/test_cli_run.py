"""The ``run`` sub-command's flags (Rerun outputs, ROS 2), parsed by the real parser and validated as a config."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.ros2_robot import StereoRig, write_bag
from vpp_service.cli import build_parser
from vpp_service.cli.run import overrides_from_args
from vpp_service.service.config import DEFAULT_CONFIG, validate_config
from vpp_service.settings import SettingsError

CONFIGURED = {**DEFAULT_CONFIG, "sinks": [{"type": "zenoh"}, {"type": "rerun", "max_hz": 2.5, "path": "x.rrd"}]}


def sinks_for(*argv: str) -> list[tuple[str, object]]:
    args = build_parser().parse_args(["run", *argv])
    cfg = validate_config(overrides_from_args(CONFIGURED, args))
    return [(s.name, s.options) for s in cfg.sinks]


@pytest.mark.parametrize(
    ("argv", "mode", "where"),
    [
        (["--rerun-save", "y.rrd"], "save", ("path", "y.rrd")),
        (["--rerun-connect"], "connect", ("url", "rerun+http://127.0.0.1:9876/proxy")),
        (
            ["--rerun-connect", "rerun+http://10.0.0.5:9000/proxy"],
            "connect",
            ("url", "rerun+http://10.0.0.5:9000/proxy"),
        ),
        (["--rerun-serve"], "serve", ("grpc_port", 9876)),
        (["--rerun-serve", "9100"], "serve", ("grpc_port", 9100)),
        (["--rerun-spawn"], "spawn", ("mode", "spawn")),
    ],
)
def test_rerun_flags_choose_the_output_and_keep_other_options(argv, mode, where):
    sinks = sinks_for(*argv)
    assert [n for n, _ in sinks] == ["zenoh", "rerun"]
    opts = sinks[1][1]
    assert opts.mode == mode and getattr(opts, where[0]) == where[1]
    assert opts.max_hz == 2.5  # the configured sink's other options stay
    assert opts.bind == "127.0.0.1"


def test_headless_drops_rerun():
    assert [n for n, _ in sinks_for("--headless")] == ["zenoh"]
    assert [n for n, _ in sinks_for()] == ["zenoh", "rerun"]


def test_rerun_flags_exclude_each_other(capsys):
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args(["run", "--rerun-spawn", "--headless"])
    assert exc.value.code == 2 and "not allowed with" in capsys.readouterr().err


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
