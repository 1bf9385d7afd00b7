"""rosbag2 sink: results recorded as a bag (MCAP and sqlite3), read back with rosbags."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
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


#: RMW_DURATION_INFINITE ({9223372036, 854775807}): what an rmw_zenoh graph reports for a publisher token
#: that leaves deadline, lifespan and liveliness lease empty (rmw_zenoh's default QoS), as ours do.
INFINITE = {"sec": 9223372036, "nsec": 854775807}


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
@pytest.mark.parametrize(
    ("distro", "version", "profiles"),
    [
        # Jazzy's recorder (metadata version 9): a YAML list, enums by name (rmw's *_to_str)
        (
            "jazzy",
            9,
            [
                {
                    "history": "keep_last",
                    "depth": 10,
                    "reliability": "reliable",
                    "durability": "volatile",
                    "deadline": INFINITE,
                    "lifespan": INFINITE,
                    "liveliness": "automatic",
                    "liveliness_lease_duration": INFINITE,
                    "avoid_ros_namespace_conventions": False,
                }
            ],
        ),
        # Humble's form: the list as one YAML string, enums as rmw integers (keep_last 1, reliable 1,
        # volatile 2, automatic 1)
        (
            "humble",
            8,
            [
                {
                    "history": 1,
                    "depth": 10,
                    "reliability": 1,
                    "durability": 2,
                    "deadline": INFINITE,
                    "lifespan": INFINITE,
                    "liveliness": 1,
                    "liveliness_lease_duration": INFINITE,
                    "avoid_ros_namespace_conventions": False,
                }
            ],
        ),
    ],
)
def test_offered_qos_and_distro_recorded(tmp_path, storage, distro, version, profiles):
    path = tmp_path / "bag"
    opts = {"path": str(path), "storage": storage, "outputs": ["disparity", "left_vpp"], "ros_distro": distro}
    sink = build_sink("rosbag2", opts)
    sink.open()
    res = result(5)
    res.left_vpp = np.zeros((4, 5, 3), np.uint8)
    sink.write(res)
    sink.close(5.0)
    info = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["ros_distro"] == distro and info["version"] == version
    for t in info["topics_with_message_count"]:
        offered = t["topic_metadata"]["offered_qos_profiles"]
        if distro == "humble":
            assert isinstance(offered, str)  # Humble's TopicMetadata holds the profiles as a YAML string
            offered = yaml.safe_load(offered)
        assert offered == profiles, t["topic_metadata"]["name"]
    # an independent reader: the same profile on both topics (the painted pair's publisher offers the same)
    infinite = QosTime(**INFINITE)
    want = Qos(
        QosHistory.KEEP_LAST, 10, QosReliability.RELIABLE, QosDurability.VOLATILE,
        infinite, infinite, QosLiveliness.AUTOMATIC, infinite, False,
    )  # fmt: skip
    with Reader(path) as reader:
        assert reader.ros_distro == distro
        assert {c.topic: c.ext.offered_qos_profiles for c in reader.connections} == {
            "/stereo/disparity": [want],
            "/stereo/left/image_vpp": [want],
        }
    # the copy inside the storage file (what rosbag2 reads when metadata.yaml is missing) names the distro too
    (data,) = [p for p in path.iterdir() if p.suffix in (".mcap", ".db3")]
    if storage == "sqlite3":
        import sqlite3

        with sqlite3.connect(data) as db:
            assert db.execute("SELECT ros_distro FROM schema").fetchall() == [(distro,)]
            (meta,) = db.execute("SELECT metadata FROM metadata").fetchone()
    else:
        raw = data.read_bytes()
        meta = raw[raw.index(b"compression_format") :].decode("utf8", "replace")
    assert f"ros_distro: {distro}\n" in meta and "rosbags" not in meta


def test_bad_ros_distro_refused(tmp_path):
    with pytest.raises(SettingsError, match="ros_distro"):
        parse_sink_options("rosbag2", {"path": str(tmp_path / "b"), "ros_distro": "iron"})
