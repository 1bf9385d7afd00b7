"""Bags through the service, and ``publish --rosbag`` onto rmw_zenoh topics.

A bag written with rosbags from the Motorcycle scene (.mcap and .db3) is played through the
service, the outputs are recorded to MCAP by the rosbag2 sink and read back.
"""

from __future__ import annotations

import numpy as np
import pytest
import zenoh
from rosbags.rosbag2 import Reader

from helpers.ros2_robot import TS, key, motorcycle_rig, write_bag
from helpers.zenoh_loopback import collect, free_port, zenoh_test_config
from vpp_service.cli import main as cli_main
from vpp_service.evaluation.metrics import compute_metrics
from vpp_service.service.app import run_service
from vpp_service.service.config import validate_config

MAXD = 96


@pytest.mark.slow
@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_bag_through_the_service_recorded_to_mcap(tmp_path, storage):
    rig, gt, doffs = motorcycle_rig()
    stamps = [2_000_000_000, 2_100_000_000]
    write_bag(str(tmp_path / "in"), storage, rig, stamps)
    out = tmp_path / "out"
    cfg = validate_config(
        {
            "service": {"out": str(tmp_path / "run"), "summary": False},
            "zenoh": {"enabled": False},
            "source": {"type": "rosbag2", "path": str(tmp_path / "in"), "rate": 0.0},
            "matcher": {"name": "sgbm", "max_disparity": MAXD},
            "queues": {"input_policy": "block", "output_policy": "block"},
            "sinks": [{"type": "rosbag2", "path": str(out), "outputs": ["disparity", "points2"]}],
        }
    )
    status = run_service(cfg, None, None)
    assert status["counters"]["processed"] == 2 and status["counters"]["no_depth"] == 0
    assert len(list(out.glob("*.mcap"))) == 1
    with Reader(out) as reader:
        msgs = [(c.topic, TS.deserialize_cdr(raw, c.msgtype)) for c, _, raw in reader.messages()]
    disp = [m for t, m in msgs if t == "/stereo/disparity"]
    clouds = [m for t, m in msgs if t == "/stereo/points2"]
    assert len(disp) == 2 and len(clouds) == 2
    assert [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in disp] == stamps
    d = disp[0].image.data.view("<f4").reshape(disp[0].image.height, -1).astype(np.float32)
    d[d < disp[0].min_disparity] = np.nan
    assert compute_metrics(d - np.float32(doffs), gt)["bad2"] < 21.0  # as the live loopback (20.5; 22.6 without VPP)
    assert clouds[0].width > 1000 and [f.name for f in clouds[0].fields] == ["x", "y", "z", "rgb"]


def test_publish_rosbag_onto_rmw_zenoh_topics(tmp_path):
    rig, _, _ = motorcycle_rig()
    write_bag(str(tmp_path / "in"), "mcap", rig, [3_000_000_000])
    ep = f"tcp/127.0.0.1:{free_port()}"
    with zenoh.open(zenoh_test_config(listen=[ep])) as s:
        sub = s.declare_subscriber(
            key(0, "/stereo/left/camera_info", "sensor_msgs/msg/CameraInfo"), zenoh.handlers.FifoChannel(8)
        )
        rc = cli_main(["publish", "--rosbag", str(tmp_path / "in"), "--rosbag-rate", "0", "--connect", ep])
        (sample,) = collect(sub, 1)
    assert rc == 0
    att = sample.attachment.to_bytes()
    assert len(att) == 33 and int.from_bytes(att[:8], "little") == 1
    info = TS.deserialize_cdr(sample.payload.to_bytes(), "sensor_msgs/msg/CameraInfo")
    assert info.header.stamp.sec == 3 and info.p[0] == pytest.approx(rig.f)
