"""ros2 sink over real Zenoh sessions: every output on its key, attachments (both layouts), lazy outputs."""

from __future__ import annotations

import logging
import time

import numpy as np
import pytest
import zenoh

from helpers.ros2_robot import TS, key
from helpers.zenoh_loopback import collect
from vpp_service.frame import Calibration, FusionResult, StereoFrame
from vpp_service.settings import SettingsError
from vpp_service.sinks.base import SinkContext, build_sink, parse_sink_options
from vpp_service.sinks.ros2 import Ros2Encoder, Ros2OutputOptions


def result() -> FusionResult:
    rng = np.random.default_rng(0)
    left = rng.integers(0, 256, (4, 5, 3), dtype=np.uint8)
    calib = Calibration(f=100.0, baseline=0.2, doffs=3.0, cx=2.0, cy=1.5)
    disp = np.full((4, 5), 7.0, np.float32)
    disp[0, 0] = np.nan
    depth = (100.0 * 0.2 / (disp + 3.0)).astype(np.float32)
    frame = StereoFrame(left=left, right=left, calib=calib, stamp_ns=9, meta={"ros": {"stamp_ns": 77, "frame_id": "L"}})
    conf = np.linspace(0, 1, 20, dtype=np.float32).reshape(4, 5)
    conf[0, 0] = 0.0  # no answer, no confidence
    return FusionResult(
        frame=frame, disparity=disp, depth=depth, confidence=conf, left_vpp=left, right_vpp=left[:, :, 0]
    )


TOPICS = {
    "disparity": ("/cam/disparity", "stereo_msgs/msg/DisparityImage"),
    "depth": ("/cam/depth", "sensor_msgs/msg/Image"),
    "confidence": ("/cam/confidence", "sensor_msgs/msg/Image"),
    "points2": ("/cam/points2", "sensor_msgs/msg/PointCloud2"),
    "left_vpp": ("/cam/left/image_vpp", "sensor_msgs/msg/Image"),
    "right_vpp": ("/cam/right/image_vpp", "sensor_msgs/msg/Image"),
}


@pytest.mark.parametrize("layout", ["current", "legacy"])
def test_all_outputs(sessions, layout):
    svc, bot = sessions
    subs = {n: bot.declare_subscriber(key(4, t, ty), zenoh.handlers.FifoChannel(8)) for n, (t, ty) in TOPICS.items()}
    opts = {"namespace": "/cam", "domain_id": 4, "outputs": list(TOPICS), "attachment": layout}
    sink = build_sink("ros2", opts, SinkContext(session=svc))
    sink.open()
    time.sleep(0.3)
    try:
        sink.write(result())
        got = {n: collect(s, 1) for n, s in subs.items()}
    finally:
        sink.close(2.0)
    assert all(len(v) == 1 for v in got.values()), {n: len(v) for n, v in got.items()}
    msgs = {n: TS.deserialize_cdr(got[n][0].payload.to_bytes(), TOPICS[n][1]) for n in TOPICS}
    for n in TOPICS:
        att = got[n][0].attachment.to_bytes()
        assert len(att) == (33 if layout == "current" else 77) and int.from_bytes(att[-25:-17], "little") >= 0
        h = msgs[n].header
        assert (h.stamp.sec, h.stamp.nanosec, h.frame_id) == (0, 77, "L")
    d = msgs["disparity"]
    img = d.image.data.view("<f4").reshape(4, 5)
    assert img[1, 1] == 10.0 and img[0, 0] < d.min_disparity and d.min_disparity == 3.0
    assert d.f == 100.0 and d.t == pytest.approx(0.2)
    assert msgs["depth"].encoding == "32FC1" and np.isnan(msgs["depth"].data.view("<f4")[0])
    conf = msgs["confidence"]
    assert (conf.encoding, conf.height, conf.width, conf.step) == ("32FC1", 4, 5, 20)
    np.testing.assert_array_equal(conf.data.view("<f4").reshape(4, 5), result().confidence)
    cloud = msgs["points2"]  # organized by default, as stereo_image_proc's points2
    assert (cloud.height, cloud.width, cloud.is_dense) == (4, 5, False)
    assert [f.name for f in cloud.fields] == ["x", "y", "z", "rgb"]
    pts = cloud.data.view("<f4").reshape(4, 5, 4)
    assert np.isnan(pts[0, 0, :3]).all()  # pixel (0, 0) has no disparity
    assert pts[0, 1, 2] == pytest.approx(2.0) and pts[0, 1, 0] == pytest.approx((1 - 2.0) * 2.0 / 100.0)
    assert msgs["left_vpp"].encoding == "rgb8" and msgs["right_vpp"].encoding == "rgb8"
    assert sink.stats()["written"] == 1


# The data key each distro's rmw_zenoh subscriber listens on (``TopicInfo::TopicInfo`` in liveliness_utils.cpp:
# domain/topic/type/hash; the humble branch's SubscriptionData::make passes the constant "TypeHashNotSupported",
# jazzy's the RIHS01 hash), and the subscriber token it declares (``Entity::Entity``; SensorDataQoS "2::,5:,:,:,,").
DISTRO_HASH = {"humble": "TypeHashNotSupported", "jazzy": key(0, "/x", TOPICS["disparity"][1]).rsplit("/", 1)[1]}
DDS_DISP = "stereo_msgs::msg::dds_::DisparityImage_"


def ros_subscriber(session: zenoh.Session, distro: str, topic: str = "/stereo/disparity", eid: int = 1):
    """An rmw_zenoh subscriber of ``distro`` on ``topic``: its exact data key and its token."""
    h = DISTRO_HASH[distro]
    tok = session.liveliness().declare_token(
        f"@ros2_lv/0/{session.zid()}/0/{eid}/MS/%/%stereo/viewer/{topic.replace('/', '%')}/{DDS_DISP}/{h}/2::,5:,:,:,,"
    )
    sub = session.declare_subscriber(f"0/{topic.strip('/')}/{DDS_DISP}/{h}", zenoh.handlers.FifoChannel(8))
    return sub, tok


@pytest.mark.parametrize("distro", ["humble", "jazzy"])
def test_subscriber_of_the_distro_receives_disparity(sessions, distro):
    """A Humble-style and a Jazzy-style subscriber (exact key, token) both get the DisparityImage, lazy or not."""
    svc, bot = sessions
    sub, tok = ros_subscriber(bot, distro)
    sink = build_sink("ros2", {"ros_distro": distro, "lazy": True}, SinkContext(session=svc))
    sink.open()
    time.sleep(0.3)
    try:
        for _ in range(3):
            sink.write(result())
        got = collect(sub, 3)
    finally:
        sink.close(2.0)
        tok.undeclare()
    assert len(got) == 3
    msg = TS.deserialize_cdr(got[0].payload.to_bytes(), TOPICS["disparity"][1])
    assert msg.image.encoding == "32FC1" and (msg.image.height, msg.image.width) == (4, 5)
    assert [int.from_bytes(s.attachment.to_bytes()[:8], "little") for s in got] == [1, 2, 3]
    assert sink.stats()["lazy_skipped"] == 0


def test_lazy_wakes_for_ros_subscriber_tokens_only(sessions):
    """A wildcard capture (plain Zenoh) keeps lazy outputs asleep; a subscriber token wakes only its output."""
    svc, bot = sessions
    capture = bot.declare_subscriber("0/stereo/**", zenoh.handlers.FifoChannel(64))
    sub, tok = ros_subscriber(bot, "jazzy")
    sink = build_sink("ros2", {"outputs": ["disparity", "depth"], "lazy": True}, SinkContext(session=svc))
    sink.open()
    time.sleep(0.3)
    try:
        sink.write(result())
        assert len(collect(sub, 1)) == 1
        captured = collect(capture, 2, timeout=0.5)
    finally:
        sink.close(2.0)
        tok.undeclare()
        capture.undeclare()
    assert [str(s.key_expr).split("/")[2] for s in captured] == ["disparity"]
    st = sink.stats()
    assert st["lazy_skipped"] == 1 and st["written"] == 1


def test_frame_without_ros_header_uses_options(sessions):
    svc, bot = sessions
    sub = bot.declare_subscriber(key(0, "/stereo/disparity", TOPICS["disparity"][1]), zenoh.handlers.FifoChannel(8))
    sink = build_sink("ros2", {"frame_id": "cam0", "invalid": "nan"}, SinkContext(session=svc))
    sink.open()
    time.sleep(0.3)
    r = result()
    r.frame.meta.clear()
    try:
        sink.write(r)
        (sample,) = collect(sub, 1)
    finally:
        sink.close(2.0)
    msg = TS.deserialize_cdr(sample.payload.to_bytes(), TOPICS["disparity"][1])
    assert msg.header.frame_id == "cam0" and msg.header.stamp.nanosec == 9
    assert np.isnan(msg.image.data.view("<f4")[0])


def test_needs_depth():
    from vpp_service.sinks.ros2 import Ros2Sink

    assert not Ros2Sink.needs_depth(parse_sink_options("ros2", {}))
    assert Ros2Sink.needs_depth(parse_sink_options("ros2", {"outputs": ["points2"]}))
    assert not Ros2Sink.needs_confidence(parse_sink_options("ros2", {"outputs": ["disparity", "depth"]}))
    assert Ros2Sink.needs_confidence(parse_sink_options("ros2", {"outputs": ["confidence"]}))


@pytest.mark.parametrize(
    "opts",
    [
        {"outputs": []},
        {"outputs": ["disparity", "disparity"]},
        {"outputs": ["certainty"]},
        {"topics": {"disparity": "bad name"}},
        {"attachment": "v2"},
        {"delta_d": 0.0},
        {"domain_id": -1},
        {"ros_distro": "iron"},
    ],
)
def test_bad_options(opts):
    with pytest.raises(SettingsError):
        parse_sink_options("ros2", opts)


@pytest.mark.parametrize("layout", ["organized", "valid_only"])
def test_points2_layouts(layout):
    """organized: one point per pixel, row by row, NaN where the depth is invalid (colour kept); valid_only: height 1.

    result(): f 100, cx 2, cy 1.5, disparity 7 + doffs 3 -> Z = 100 x 0.2 / 10 = 2 m everywhere but pixel (0, 0).
    """
    res = result()
    opts = Ros2OutputOptions(outputs=["points2"], points2_layout=layout)
    payload = Ros2Encoder(opts).encode(res, "points2")
    cloud = TS.deserialize_cdr(bytes(payload), "sensor_msgs/msg/PointCloud2")  # an independent reader
    n = 20 if layout == "organized" else 19
    assert (cloud.height, cloud.width) == ((4, 5) if layout == "organized" else (1, 19))
    assert cloud.point_step == 16 and cloud.row_step == 16 * cloud.width and cloud.is_dense == (layout != "organized")
    rec = cloud.data.view("<f4").reshape(n, 4)
    packed = rec[:, 3].view("<u4")
    left = res.frame.left.reshape(-1, 3).astype(np.uint32)
    want_rgb = (left[:, 0] << 16) | (left[:, 1] << 8) | left[:, 2]
    if layout == "organized":
        v, u = np.divmod(np.arange(20), 5)
        assert np.isnan(rec[0, :3]).all() and np.isfinite(rec[1:, :3]).all()
        np.testing.assert_allclose(rec[1:, 0], (u[1:] - 2.0) * 2.0 / 100.0, rtol=1e-6)
        np.testing.assert_allclose(rec[1:, 1], (v[1:] - 1.5) * 2.0 / 100.0, rtol=1e-6)
        np.testing.assert_array_equal(packed, want_rgb)  # the invalid pixel keeps its colour
    else:
        np.testing.assert_allclose(rec[:, 2], 2.0, rtol=1e-6)
        np.testing.assert_array_equal(packed, want_rgb[1:])


def test_bad_points2_layout():
    with pytest.raises(SettingsError, match="points2_layout"):
        parse_sink_options("ros2", {"points2_layout": "dense"})


def test_a_subscriber_of_another_distro_is_said(sessions, caplog):
    """A Humble-keyed subscriber next to a jazzy sink gets nothing: the sink says so, once, naming the fix."""
    svc, bot = sessions
    sub, tok = ros_subscriber(bot, "humble")
    sink = build_sink("ros2", {"ros_distro": "jazzy"}, SinkContext(session=svc))
    sink.open()
    time.sleep(0.3)
    try:
        with caplog.at_level(logging.WARNING, logger="vpp_service.sinks.ros2"):
            for _ in range(3):
                sink.write(result())
        got = collect(sub, 1, timeout=0.5)
    finally:
        sink.close(2.0)
        tok.undeclare()
    said = [r.getMessage() for r in caplog.records if "TypeHashNotSupported" in r.getMessage()]
    assert got == [] and len(said) == 1 and "/stereo/disparity" in said[0] and "ros_distro" in said[0], said
