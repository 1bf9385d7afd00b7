"""rosbag2 sink: results recorded as a bag (MCAP and sqlite3), read back with rosbags."""

from __future__ import annotations

import numpy as np
import pytest
from rosbags.rosbag2 import Reader

from helpers.ros2_robot import TS
from vpp_service.frame import Calibration, FusionResult, StereoFrame
from vpp_service.settings import SettingsError
from vpp_service.sinks.base import build_sink, parse_sink_options


def result(stamp: int) -> FusionResult:
    left = np.zeros((4, 5, 3), np.uint8)
    calib = Calibration(f=100.0, baseline=0.2, doffs=3.0)
    disp = np.full((4, 5), 7.0, np.float32)
    frame = StereoFrame(left=left, right=left, calib=calib, meta={"ros": {"stamp_ns": stamp, "frame_id": "L"}})
    return FusionResult(frame=frame, disparity=disp, depth=np.full((4, 5), 2.0, np.float32))


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_recorded_and_read_back(tmp_path, storage):
    path = tmp_path / "out" / "bag"
    sink = build_sink("rosbag2", {"path": str(path), "storage": storage, "outputs": ["disparity", "depth"]})
    sink.open()
    for stamp in (5, 6, 7):
        sink.write(result(stamp))
    sink.close(5.0)
    assert sink.stats()["written"] == 3 and sink.stats()["messages"] == 6
    with Reader(path) as reader:
        topics = {c.topic: c.msgtype for c in reader.connections}
        assert topics == {
            "/stereo/disparity": "stereo_msgs/msg/DisparityImage",
            "/stereo/depth": "sensor_msgs/msg/Image",
        }
        got = [(c.topic, t, TS.deserialize_cdr(raw, c.msgtype)) for c, t, raw in reader.messages()]
    disp = [(t, m) for topic, t, m in got if topic == "/stereo/disparity"]
    assert [t for t, _ in disp] == [5, 6, 7]
    assert disp[0][1].header.frame_id == "L" and disp[0][1].image.data.view("<f4")[0] == 10.0


def test_existing_path_refused(tmp_path):
    with pytest.raises(SettingsError, match="exists already"):
        parse_sink_options("rosbag2", {"path": str(tmp_path)})
    with pytest.raises(SettingsError, match="path"):
        parse_sink_options("rosbag2", {})
