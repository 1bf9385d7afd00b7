"""ros2 source over real Zenoh sessions on 127.0.0.1: tokens, both attachment layouts, refusals, frames."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
import zenoh

from helpers.ros2_robot import Robot, StereoRig, camera_info_from_p, cloud_msg, image_msg, tf_message
from helpers.zenoh_loopback import zenoh_test_config
from vpp_service.sources.base import SourceContext, build_source

LEGACY = (
    b"\x0fsequence_number" + (1).to_bytes(8, "little") + b"\x10source_timestamp" + (5).to_bytes(8, "little")
    + b"\x0asource_gid\x10" + bytes(16)
)  # fmt: skip


def tiny_rig() -> StereoRig:
    rng = np.random.default_rng(0)
    img = rng.integers(0, 256, (6, 8, 3), dtype=np.uint8)
    return StereoRig(img, img, 100.0, 0.1, 3.5, 5.5, 2.5, np.array([[0, 0, 2.0]], np.float32))


def wait_for(cond, timeout=5.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and not cond():
        time.sleep(0.01)
    return cond()


def test_frames_tokens_and_attachments(sessions):
    svc, bot = sessions
    src = build_source("ros2", {"domain_id": 0, "depth_wait_ms": 2000.0}, SourceContext(rig="r", session=svc))
    frames, rejects = [], []
    src.open()
    src.start(lambda f: frames.append(f) or True, rejects.append)
    robot = Robot(bot)
    try:
        names = ["left/image_rect", "left/camera_info", "right/image_rect", "right/camera_info", "points"]
        assert robot.wait_for_subscribers(names)
        # the graph's history reply may bring the node token after the subscribers' tokens
        assert wait_for(lambda: any("/NN/%/%stereo/vpp_stereo_input" in t for t in robot.graph()))
        rig = tiny_rig()
        robot.publish(rig, 1_000)
        assert wait_for(lambda: len(frames) == 1)
        assert frames[0].sensor_depth[2, 4] == pytest.approx(2.0) and frames[0].calib.doffs == 2.0
        # the older labelled layout is accepted; a sample without attachment is refused and counted
        for name in ("left/image_rect", "right/image_rect"):
            robot.put(name, image_msg(rig.left, 2_000, "l"), LEGACY)
        robot.pubs["left/camera_info"].put(b"\x00\x01\x00\x00")  # no attachment
        assert wait_for(lambda: src.stats()["received"] == 8)
        st = src.stats()
        assert st["attachment_legacy"] == 2 and st["rejected_by"] == {"attachment": 1} and st["rejected"] == 1
        assert any("attachment" in r for r in rejects)
    finally:
        robot.close()
        src.stop(2.0)


# A subscriber token as rmw_zenoh builds it (``Entity::Entity``, liveliness_utils.cpp): the type-hash chunk is the
# humble branch's constant "TypeHashNotSupported" or jazzy's RIHS01 hash; the QoS chunk leaves rmw_zenoh's defaults
# (reliable, volatile, keep last, depth 42: qos.cpp) empty, so best effort + keep last 3 is "2::,3:,:,:,," and
# best effort + keep all 3 is "2::2,3:,:,:,,".
@pytest.mark.parametrize(
    ("distro", "policy", "hash_", "qos"),
    [
        ("humble", "latest", "TypeHashNotSupported", "2::,3:,:,:,,"),
        ("jazzy", "latest", "RIHS01_d31d41a9a4c4bc8eae9be757b0beed306564f7526c88ea6a4588fb9582527d47", "2::,3:,:,:,,"),
        ("jazzy", "block", "RIHS01_d31d41a9a4c4bc8eae9be757b0beed306564f7526c88ea6a4588fb9582527d47", "2::2,3:,:,:,,"),
    ],
)
def test_subscriber_tokens_follow_distro_and_rings(sessions, distro, policy, hash_, qos):
    svc, bot = sessions
    opts = {"ros_distro": distro, "ring_size": 3, "depth_type": "none"}
    src = build_source("ros2", opts, SourceContext(rig="r", session=svc))
    src.input_policy = policy
    src.open()
    robot = Robot(bot)
    try:
        assert robot.wait_for_subscribers(["left/image_rect"])
        (tok,) = [t for t in robot.graph() if "/MS/" in t and "%stereo%left%image_rect/" in t]
    finally:
        robot.close()
        src.close()
    assert tok.endswith(f"/sensor_msgs::msg::dds_::Image_/{hash_}/{qos}")


def test_needs_session():
    src = build_source("ros2", {}, SourceContext())
    with pytest.raises(ValueError, match="session"):
        src.open()


@pytest.mark.parametrize(
    "opts", [{"domain_id": 300}, {"node_name": "a/b"}, {"ring_size": 0}, {"poll_s": 0.0}, {"ros_distro": "foxy"}]
)
def test_bad_options(opts):
    from vpp_service.settings import SettingsError
    from vpp_service.sources.base import parse_source_options

    with pytest.raises(SettingsError):
        parse_source_options("ros2", opts)


def test_oversized_sample_refused_before_copy(sessions):
    svc, bot = sessions
    opts = {"depth_type": "none", "max_message_mb": 0.001}  # 1048 bytes: a 6x8 camera_info fits, an image does not
    src = build_source("ros2", opts, SourceContext(rig="r", session=svc))
    frames, rejects = [], []
    src.open()
    src.start(lambda f: frames.append(f) or True, rejects.append)
    robot = Robot(bot)
    try:
        assert robot.wait_for_subscribers(["left/image_rect"])
        big = np.zeros((20, 30, 3), np.uint8)  # 1800 bytes of pixels
        robot.put("left/image_rect", image_msg(big, 1, "l"))
        assert wait_for(lambda: src.stats()["received"] == 1)
        st = src.stats()
        assert st["rejected_by"] == {"too_large": 1} and not frames and "too_large" in rejects[0]
    finally:
        robot.close()
        src.stop(2.0)


def test_ring_drops_of_the_latest_policy_reach_losses(sessions):
    """Messages that arrive while the source's thread is not draining: a full ring drops the oldest, counted."""
    svc, bot = sessions
    src = build_source("ros2", {"ring_size": 2}, SourceContext(rig="r", session=svc))
    src.open()  # subscribed, thread not started: nothing drains the rings
    robot = Robot(bot)
    try:
        assert robot.wait_for_subscribers(["left/image_rect"])
        rig = tiny_rig()
        for k in range(5):
            robot.put("left/image_rect", image_msg(rig.left, 1_000 + k, "l"))
        assert wait_for(lambda: src.stats()["ring_dropped"] == 3)
        assert src.losses()["source_ring"] == 3
    finally:
        robot.close()
        src.stop(2.0)


@pytest.mark.parametrize("policy", ["block", "latest"])
def test_overload_loses_nothing_under_block_and_counts_every_drop_under_latest(sessions, policy):
    """12 sets sent as fast as possible to a slow pipeline (and one set whose image is rejected)."""
    from vpp_service.frame import FusionResult
    from vpp_service.service.pipeline import Pipeline

    svc, bot = sessions
    # rings deep enough for every message: the overload meets the pipeline's input queue, in frames
    opts = {"depth_wait_ms": 2000.0, "ring_size": 100, "sync_queue_size": 32}  # a 13-set burst fits the sync
    src = build_source("ros2", opts, SourceContext(rig="r", session=svc))

    def slow(frame):
        time.sleep(0.05)
        return FusionResult(frame=frame, disparity=np.zeros(frame.shape, np.float32), timing_ms={"match": 50.0})

    pipe = Pipeline(src, slow, [], input_size=1, input_policy=policy, rig="r")
    pipe.start()
    robot = Robot(bot)
    try:
        assert robot.wait_for_subscribers(["left/image_rect", "right/image_rect", "points"])
        rig = tiny_rig()
        h, w = rig.left.shape[:2]  # one whole set whose left image is 8UC4: joined, then refused
        robot.put("left/image_rect", image_msg(np.zeros((h, w, 4), np.uint8), 400, "l", encoding="8UC4"))
        robot.put("right/image_rect", image_msg(rig.right, 400, "r"))
        robot.put("left/camera_info", camera_info_from_p(400, "l", (w, h), rig.projection(right=False)))
        robot.put("right/camera_info", camera_info_from_p(400, "r", (w, h), rig.projection(right=True)))
        robot.put("points", cloud_msg(rig.cloud, 400, "l"))
        for k in range(12):
            robot.publish(rig, 1_000 + k)
        sent = 12
        arrived = wait_for(
            lambda: pipe.status()["counters"]["processed"] + pipe.status()["dropped"].get("input_queue", 0) >= sent,
            timeout=30,
        )
        assert arrived, pipe.status()
        time.sleep(0.3)
        st = pipe.status()
    finally:
        robot.close()
        pipe.stop(2.0)
    c, d = st["counters"], st["dropped"]
    assert c["rejected"] >= 1 and st["source"]["rejected_by"], st["source"]
    # the refused image never enters the synchronizer: the other parts of its set are left without a partner
    # and counted as sync drops (at most its 4 other parts); no genuine set is lost under block
    assert d["sync"] <= 4, d
    if policy == "block":
        assert c["processed"] == sent and c["dropped"] == d["sync"], d
    else:
        assert c["processed"] + d["input_queue"] == sent and d["input_queue"] > 0, d
        assert c["dropped"] == sum(d.values()) == d["input_queue"] + d["sync"], d


@pytest.mark.parametrize(
    ("bad", "cause"),
    [
        ("encoding", "encoding"),
        ("step", "layout"),
        ("info", "calibration"),
    ],
)
def test_a_bad_part_with_the_genuine_stamp_does_not_take_its_slot(sessions, bad, cause):
    """Well-formed CDR, bad content, the genuine set's stamp, sent first: refused; the genuine set completes."""
    svc, bot = sessions
    src = build_source("ros2", {"depth_wait_ms": 2000.0}, SourceContext(rig="r", session=svc))
    frames, rejects = [], []
    src.open()
    src.start(lambda f: frames.append(f) or True, rejects.append)
    robot = Robot(bot)
    try:
        assert robot.wait_for_subscribers(["left/image_rect", "left/camera_info", "points"])
        rig = tiny_rig()
        h, w = rig.left.shape[:2]
        if bad == "encoding":
            robot.put("left/image_rect", image_msg(rig.left, 1_000, "l", encoding="8UC4"))
        elif bad == "step":
            msg = image_msg(rig.left, 1_000, "l")
            msg.step = w * 3 + 7  # step x height no longer matches the data
            robot.put("left/image_rect", msg)
        else:
            robot.put("left/camera_info", camera_info_from_p(1_000, "l", (w, h), np.zeros((3, 4))))
        robot.publish(rig, 1_000)  # the genuine set, same stamp
        assert wait_for(lambda: len(frames) == 1), src.stats()
        st = src.stats()
        assert st["rejected"] == 1 and st["rejected_by"] == {cause: 1}, st["rejected_by"]
        assert frames[0].stamp_ns == 1_000 and frames[0].left.shape[:2] == (h, w)
    finally:
        robot.close()
        src.stop(2.0)


def test_a_junk_burst_never_takes_a_ring_slot(sessions):
    """Junk (no rmw_zenoh attachment, or oversized) after genuine sets, 4-deep rings, latest policy.

    The drain is held inside ``emit`` while three genuine sets, each followed by 96 junk samples on every
    topic, arrive: the rings then hold exactly the 3 genuine messages per topic, whatever the scheduling. A
    junk sample that took a ring slot would push a genuine one out of its 4-deep ring (``ring_dropped``).
    """
    svc, bot = sessions
    opts = {"depth_wait_ms": 5000.0, "ring_size": 4, "max_message_mb": 0.01}
    src = build_source("ros2", opts, SourceContext(rig="r", session=svc))
    frames: list = []
    held = threading.Event()

    def emit(frame) -> bool:
        frames.append(frame)
        if len(frames) == 1:  # hold the drain: nothing leaves the rings until released
            held.wait(30)
        return True

    src.open()  # the pipeline's default input policy: latest
    robot = Robot(bot)
    names = list(robot.topics)
    try:
        assert robot.wait_for_subscribers(["left/image_rect", "right/image_rect", "points"])
        src.start(emit, lambda reason: None)
        rig = tiny_rig()
        robot.publish(rig, 1_000)
        assert wait_for(lambda: len(frames) == 1, timeout=20), src.stats()
        for k in range(1, 4):
            robot.publish(rig, 1_000 + k)
            for j in range(96):  # after the genuine set on the same publishers: a slot taken would evict it
                if j % 2:  # no attachment: not an rmw_zenoh publisher
                    robot.pubs[names[j // 2 % len(names)]].put(b"\x00\x01\x00\x00junk")
                else:  # 12 KB > max_message_mb
                    robot.put(
                        ("left/image_rect", "right/image_rect")[j // 2 % 2],
                        image_msg(np.zeros((64, 64, 3), np.uint8), 9, "j"),
                    )

        def all_in() -> bool:
            st = src.stats()
            return st["received"] == 5 * 4 + 3 * 96 and st["messages"]["unmatched"] == 5 * 3  # type: ignore[index]

        assert wait_for(all_in, timeout=20), src.stats()
        held.set()
        assert wait_for(lambda: len(frames) == 4, timeout=20), src.stats()
        st = src.stats()
    finally:
        held.set()
        robot.close()
        src.stop(2.0)
    assert st["ring_dropped"] == 0 and st["rejected"] == 3 * 96, st
    assert st["rejected_by"]["attachment"] == 3 * 48 and st["rejected_by"]["too_large"] == 3 * 48
    assert [f.stamp_ns for f in frames] == [1_000 + k for k in range(4)]


def test_every_received_message_ends_in_exactly_one_count(sessions):
    """A rejected set, a junk burst, a set refused whole, three good sets and a half set left at shutdown.

    Expected ends (J = 24 junk samples): used 3 x 5; rejected J + 1 (the 8UC4 image) + 4 (the set
    whose camera_info has another size); sync_dropped 3 (the 8UC4 set's partners, passed over by the
    next match); unmatched 4 (the two clouds no set took, the half set's 2 parts).
    """
    svc, bot = sessions
    opts = {"depth_wait_ms": 2000.0, "ring_size": 64, "max_message_mb": 0.01}
    src = build_source("ros2", opts, SourceContext(rig="r", session=svc))
    frames: list = []
    src.open()
    src.start(lambda f: frames.append(f) or True, lambda reason: None)
    robot = Robot(bot)
    try:
        assert robot.wait_for_subscribers(["left/image_rect", "right/image_rect", "points"])
        rig = tiny_rig()
        h, w = rig.left.shape[:2]
        # a set whose left image is 8UC4: the image is refused, its 3 partners and its cloud stay behind
        robot.put("left/image_rect", image_msg(np.zeros((h, w, 4), np.uint8), 400, "l", encoding="8UC4"))
        robot.put("right/image_rect", image_msg(rig.right, 400, "r"))
        robot.put("left/camera_info", camera_info_from_p(400, "l", (w, h), rig.projection(right=False)))
        robot.put("right/camera_info", camera_info_from_p(400, "r", (w, h), rig.projection(right=True)))
        robot.put("points", cloud_msg(np.array([[0, 0, -1.0]], np.float32), 400, "l"))  # a point behind the camera
        for j in range(24):  # junk: no attachment, or over max_message_mb
            if j % 2:
                robot.pubs["left/camera_info"].put(b"\x00\x01\x00\x00junk")
            else:
                robot.put("right/image_rect", image_msg(np.zeros((64, 64, 3), np.uint8), 9, "j"))
        for k in range(3):
            robot.publish(rig, 1_000 + k)
        # a set whose camera_info is for another image size: joined, then refused whole (4 messages)
        robot.put("left/image_rect", image_msg(rig.left, 2_000, "l"))
        robot.put("right/image_rect", image_msg(rig.right, 2_000, "r"))
        robot.put("left/camera_info", camera_info_from_p(2_000, "l", (w + 2, h), rig.projection(right=False)))
        robot.put("right/camera_info", camera_info_from_p(2_000, "r", (w + 2, h), rig.projection(right=True)))
        robot.put("points", cloud_msg(rig.cloud, 2_000, "l"))
        # half a set: pending at shutdown
        robot.put("left/image_rect", image_msg(rig.left, 5_000, "l"))
        robot.put("left/camera_info", camera_info_from_p(5_000, "l", (w, h), rig.projection(right=False)))
        sent = 5 + 24 + 3 * 5 + 5 + 2
        assert wait_for(lambda: src.stats()["messages"]["unmatched"] == 4 and len(frames) == 3, timeout=10)
        assert wait_for(lambda: src.stats()["messages"]["received"] == sent)
    finally:
        robot.close()
        src.stop(2.0)
    m = src.stats()["messages"]
    assert m == {
        "received": sent,
        "used": 15,
        "rejected": 24 + 1 + 4,
        "ring_dropped": 0,
        "sync_dropped": 3,
        "pending_dropped": 0,
        "depth_unused": 0,
        "unmatched": 4,
    }, m
    assert m["received"] == sum(v for k, v in m.items() if k != "received")
    assert [f.stamp_ns for f in frames] == [1_000, 1_001, 1_002]
    # each good set took its own cloud (one point in view), not the rejected set's (stamped 0.6 us earlier,
    # within the tolerance, its one point behind the camera)
    assert all(np.isfinite(f.sensor_depth).sum() == 1 for f in frames)


def send_set_with_lidar_cloud(robot: Robot) -> None:
    """One set at stamp 1000 whose cloud, the point (0, 0, 2.5), is in the frame 'lidar' (the cloud first)."""
    rig = tiny_rig()
    h, w = rig.left.shape[:2]
    robot.put("points", cloud_msg(np.array([[0.0, 0.0, 2.5]], np.float32), 1_000, "lidar"))
    robot.put("left/image_rect", image_msg(rig.left, 1_000, "left_optical"))
    robot.put("right/image_rect", image_msg(rig.right, 1_000, "right_optical"))
    robot.put("left/camera_info", camera_info_from_p(1_000, "left_optical", (w, h), rig.projection(right=False)))
    robot.put("right/camera_info", camera_info_from_p(1_000, "right_optical", (w, h), rig.projection(right=True)))


def test_tf_static_published_before_the_source_started_is_fetched(zenoh_endpoint):
    """/tf_static is transient local on a robot: a transform sent once, before the service came, still places the cloud.

    The robot's session has timestamping on and its publisher a cache, as rmw_zenoh's; the source's
    /tf_static subscriber (tf2's static-listener QoS, transient local) asks for that history.
    """
    robot_conf = zenoh_test_config(listen=[zenoh_endpoint])
    robot_conf.insert_json5("timestamping/enabled", "true")
    with zenoh.open(robot_conf) as bot:
        robot = Robot(bot)
        robot.publish_tf_static(
            tf_message([("left_optical", "lidar", (0.0, 0.0, -0.5), (0.0, 0.0, 0.0, 1.0))]), transient_local=True
        )
        time.sleep(0.3)
        with zenoh.open(zenoh_test_config(connect=[zenoh_endpoint])) as svc:
            src = build_source("ros2", {"depth_wait_ms": 2000.0}, SourceContext(rig="r", session=svc))
            frames: list = []
            src.open()
            src.start(lambda f: frames.append(f) or True, lambda reason: None)
            try:
                assert robot.wait_for_subscribers(["left/image_rect", "points"])
                assert wait_for(lambda: src.stats()["tf_messages"] == 1), src.stats()
                send_set_with_lidar_cloud(robot)
                assert wait_for(lambda: len(frames) == 1), src.stats()
            finally:
                robot.close()
                src.stop(2.0)
    assert frames[0].sensor_depth[2, 4] == pytest.approx(2.0) and src.stats()["rejected_by"] == {}


def test_cloud_placed_by_tf_static(sessions):
    """A cloud in the LiDAR's own frame, 0.5 m behind the left camera: placed by the chain read from /tf_static.

    tiny_rig: f 100, cx 3.5, cy 2.5; the point (0, 0, 2.5) in 'lidar' is (0, 0, 2) in the left optical frame,
    on the principal point: pixel (rint 2.5, rint 3.5) = (2, 4) at 2 m.
    """
    svc, bot = sessions
    src = build_source("ros2", {"depth_wait_ms": 2000.0}, SourceContext(rig="r", session=svc))
    frames: list = []
    src.open()
    src.start(lambda f: frames.append(f) or True, lambda reason: None)
    robot = Robot(bot)
    try:
        assert robot.wait_for_subscribers(["left/image_rect", "points"])
        assert wait_for(lambda: any("/MS/" in t and "%tf_static/tf2_msgs::msg::dds_::TFMessage_/" in t
                                    and t.endswith("/:1:,100:,:,:,,") for t in robot.graph()))  # fmt: skip
        robot.publish_tf_static(tf_message([("left_optical", "lidar", (0.0, 0.0, -0.5), (0.0, 0.0, 0.0, 1.0))]))
        assert wait_for(lambda: src.stats()["tf_messages"] == 1)
        send_set_with_lidar_cloud(robot)
        assert wait_for(lambda: len(frames) == 1), src.stats()
    finally:
        robot.close()
        src.stop(2.0)
    assert frames[0].sensor_depth[2, 4] == pytest.approx(2.0) and np.isfinite(frames[0].sensor_depth).sum() == 1
    assert src.stats()["rejected_by"] == {}
