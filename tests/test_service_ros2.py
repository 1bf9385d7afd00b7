"""Loopback with a Zenoh router: a ROS 2 robot written from the contract <-> the service (ros2 source and sink).

The robot (tests/helpers/ros2_robot.py: rosbags + zenoh only) waits for the service's
subscriber tokens like a lazy publisher, publishes a scene (tests/helpers/ros2_scenes.py: the
Motorcycle RGB pair, or the shared data's KITTI 2012 gray pair as mono8 with its real P0/P1),
both camera_info and a PointCloud2 with attachments, and must receive a DisparityImage on the
exact key with a 33-byte attachment, a publisher token in the graph, the left camera_info header
copied, f and baseline as the project's reader has them, and bad-2 vs ground truth as good as
the same scene through the msgpack wire format; and that the same sets replayed with the cloud
published before, just after or well after the images give bit-identical maps.
"""

from __future__ import annotations

import threading
import time
from contextlib import contextmanager

import numpy as np
import pytest
import zenoh

from helpers.ros2_robot import TS, Robot, StereoRig, camera_info_from_p, cloud_msg, image_msg
from helpers.ros2_scenes import SCENES, load_scene, msgpack_bad2, plain_bad2
from helpers.zenoh_loopback import free_port, zenoh_test_config
from vpp_service.metrics import compute_metrics
from vpp_service.service.app import run_service
from vpp_service.service.config import validate_config

DISPARITY_KEY = (
    "0/stereo/disparity/stereo_msgs::msg::dds_::DisparityImage_/"
    "RIHS01_1ec1ff6b5bace919e4544a37f2d96ead9f81783701b7b7a4d97a09325ecf2711"
)


@contextmanager
def ros2_service(config: dict, topics: dict[str, str] | None = None, join_s: float = 10.0):
    """A service (``config`` plus a peer Zenoh section) behind a router, and a robot whose subscribers it has.

    Yields ``(robot, disparity subscriber, status)``; ``status`` holds the service's final status once
    the block has ended (the service stopped, the robot closed).
    """
    ep = f"tcp/127.0.0.1:{free_port()}"
    # as rmw_zenoh nodes: peers that listen on a random port and meet through the router (gossip)
    cfg = validate_config({**config, "zenoh": {"mode": "peer", "listen": ["tcp/127.0.0.1:0"], "connect": [ep]}})
    stop = threading.Event()
    status: dict = {}
    with zenoh.open(zenoh_test_config(listen=[ep], mode="router")):
        svc = threading.Thread(target=lambda: status.update(run_service(cfg, stop, None)), daemon=True)
        svc.start()
        with zenoh.open(zenoh_test_config(listen=["tcp/127.0.0.1:0"], connect=[ep])) as robot_session:
            robot = Robot(robot_session) if topics is None else Robot(robot_session, topics=topics)
            sub = robot.subscribe_disparity()
            try:
                assert robot.wait_for_subscribers(list(robot.topics), timeout=15.0), robot.graph()
                yield robot, sub, status
            finally:
                stop.set()
                svc.join(join_s)
                robot.close()


@pytest.mark.slow
@pytest.mark.parametrize("scene_name", SCENES)
def test_robot_receives_disparity(tmp_path, scene_name):
    scene = load_scene(scene_name)
    rig, gt, maxd = scene.rig, scene.gt, scene.max_disparity
    config = {
        "service": {"out": str(tmp_path / "run"), "summary": False, "shutdown_timeout_s": 3.0},
        "source": {"type": "ros2", "depth_wait_ms": 2000.0},
        "matcher": {"name": "sgbm", "max_disparity": maxd},
        "queues": {"input_policy": "block", "output_policy": "block"},
        "sinks": [{"type": "ros2", "outputs": ["disparity"], "max_disparity": float(maxd)}],
    }
    with ros2_service(config) as (robot, sub, status):
        stamp = 1_700_000_000_123_456_789
        sample = None
        deadline = time.monotonic() + 30.0
        while sample is None and time.monotonic() < deadline:
            robot.publish(rig, stamp)
            t_end = time.monotonic() + 3.0
            while sample is None and time.monotonic() < t_end:
                sample = sub.try_recv()
                time.sleep(0.02)
            stamp += 100_000_000 if sample is None else 0
        assert sample is not None, "no DisparityImage received"
        graph = robot.graph()
    assert str(sample.key_expr) == DISPARITY_KEY
    att = sample.attachment.to_bytes()
    assert len(att) == 33 and att[16] == 0x10 and int.from_bytes(att[:8], "little") >= 1
    pub_tokens = [t for t in graph if "/MP/" in t and "%stereo%disparity/stereo_msgs::msg::dds_::DisparityImage_" in t]
    assert pub_tokens and pub_tokens[0].endswith("/::2,:,:,:,,")  # reliable + keep all (BLOCK), canonical
    assert any("/NN/" in t and t.endswith("/vpp_stereo") for t in graph)
    msg = TS.deserialize_cdr(sample.payload.to_bytes(), "stereo_msgs/msg/DisparityImage")
    assert msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec == stamp
    assert msg.header.frame_id == "left_optical"
    assert msg.image.encoding == "32FC1" and msg.image.step == 4 * msg.image.width
    assert msg.f == pytest.approx(rig.f) and msg.t == pytest.approx(rig.baseline, rel=1e-6)
    # the calibration read from camera_info's P is the one the project's reader has for the scene
    assert msg.f == pytest.approx(scene.calib.f) and msg.t == pytest.approx(scene.calib.baseline, rel=1e-6)
    d = msg.image.data.view("<f4").reshape(msg.image.height, msg.image.width).astype(np.float32)
    d[d < msg.min_disparity] = np.nan  # the message definition's rule for invalid pixels
    ros_bad2 = compute_metrics(d - np.float32(scene.calib.doffs), gt)["bad2"]
    ref_bad2 = msgpack_bad2(scene)
    # same pixels, points and seed: equal up to float rounding of the calibration through P
    assert ros_bad2 <= ref_bad2 + 0.1, (ros_bad2, ref_bad2)
    assert ros_bad2 < plain_bad2(scene) - 1.0  # VPP ran on the cloud's points
    assert status["counters"]["processed"] >= 1 and status["counters"]["no_depth"] == 0


def plane_rig(d: int, seed: int) -> StereoRig:
    """A fronto-parallel textured plane at disparity ``d`` (f 500 px, baseline 0.1 m, cx_l = cx_r) and its cloud.

    The right view is the left shifted by ``d`` columns; the cloud holds 300 pixels with a right-view
    partner (``u >= d``), back-projected at ``Z = f B / d``.
    """
    h, w, f, b = 64, 256, 500.0, 0.1
    rng = np.random.default_rng(seed)
    texture = rng.integers(0, 256, (h, w + d, 3), dtype=np.uint8)
    left, right = np.ascontiguousarray(texture[:, :w]), np.ascontiguousarray(texture[:, d : d + w])  # l[u] = r[u-d]
    cx, cy = (w - 1) / 2, (h - 1) / 2
    v = rng.integers(0, h, 300)
    u = rng.integers(d, w, 300)
    z = f * b / d
    cloud = np.stack([(u - cx) * z / f, (v - cy) * z / f, np.full(300, z)], axis=1).astype(np.float32)
    return StereoRig(left, right, f, b, cx, cx, cy, cloud)


#: The publishing orders of the cloud vs the images (the last one: 0.3 s after them).
ORDERS = ("cloud_first", "cloud_last", "cloud_late")


def replay(tmp_path, rigs: list[StereoRig], stamps: list[int], order: str) -> list[bytes]:
    """Publish each set in ``order`` to a fresh service over a router, await its DisparityImage; their raw bytes."""
    config = {
        "service": {"out": str(tmp_path / order), "summary": False, "shutdown_timeout_s": 3.0},
        "source": {"type": "ros2", "depth_wait_ms": 2000.0, "depth_tolerance_ms": 50.0},
        "matcher": {"name": "sgbm", "max_disparity": "auto"},
        "queues": {"input_policy": "block", "output_policy": "block"},
        "sinks": [{"type": "ros2", "outputs": ["disparity"]}],
    }
    out: list[bytes] = []
    with ros2_service(config) as (robot, sub, _):
        for rig, stamp in zip(rigs, stamps, strict=True):
            h, w = rig.left.shape[:2]
            images = [
                ("left/image_rect", image_msg(rig.left, stamp, "left_optical")),
                ("right/image_rect", image_msg(rig.right, stamp, "right_optical")),
                ("left/camera_info", camera_info_from_p(stamp, "left_optical", (w, h), rig.projection(False))),
                ("right/camera_info", camera_info_from_p(stamp, "right_optical", (w, h), rig.projection(True))),
            ]
            cloud = ("points", cloud_msg(rig.cloud, stamp, "left_optical"))
            for k, (name, msg) in enumerate([cloud, *images] if order == "cloud_first" else [*images, cloud]):
                if order == "cloud_late" and k == 4:
                    time.sleep(0.3)
                robot.put(name, msg)
            deadline, got = time.monotonic() + 20.0, None
            while got is None and time.monotonic() < deadline:  # the reply awaited before the next set
                sample = sub.try_recv()
                if sample is None:
                    time.sleep(0.01)
                    continue
                msg = TS.deserialize_cdr(sample.payload.to_bytes(), "stereo_msgs/msg/DisparityImage")
                if msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec == stamp:
                    got = msg
            assert got is not None, f"no DisparityImage for stamp {stamp} ({order})"
            out.append(got.image.data.tobytes())
    return out


@pytest.mark.slow
def test_same_sets_give_the_same_maps_whatever_the_cloud_timing(tmp_path):
    """Three planes (disparity 20, 100, 52) 30 ms apart, auto range, one cloud per set, replies awaited.

    A set's neighbour's cloud lies within the 50 ms depth tolerance: a set that took it (its own not
    there yet) would match another scene's points and grow the range from them. Every order must
    give the maps of the first replay, bit for bit, and each map must find its plane.
    """
    disparities = [20, 100, 52]
    rigs = [plane_rig(d, seed=k) for k, d in enumerate(disparities)]
    stamps = [1_700_000_000_000_000_000 + 30_000_000 * k for k in range(3)]
    runs = {order: replay(tmp_path, rigs, stamps, order) for order in ORDERS}
    first = runs[ORDERS[0]]
    for d, raw in zip(disparities, first, strict=True):
        disp = np.frombuffer(raw, "<f4").reshape(64, 256)
        assert abs(float(np.median(disp[:, 128:])) - d) <= 1.0  # the plane found (right half: valid for any d)
    for order in ORDERS[1:]:
        assert [a == b for a, b in zip(runs[order], first, strict=True)] == [True] * 3, order


# ------------------------------------------------------------------ raw rigs: image_raw / compressed + camera_info
#: Middlebury 2005/2006 scenes (shared data) made into a raw, distorted rig (helpers.raw_rig).
RAW_SCENES = ("Art", "Books", "Moebius")
IMAGE_T, COMPRESSED_T, INFO_T = (
    "sensor_msgs/msg/Image",
    "sensor_msgs/msg/CompressedImage",
    "sensor_msgs/msg/CameraInfo",
)


def raw_rig_topics(transport: str) -> dict[str, str]:
    """What a raw rig publishes: ``image_raw`` (or its ``/compressed`` topic) and the raw camera_info."""
    if transport == "compressed":
        return {
            "left/image_raw/compressed": COMPRESSED_T,
            "right/image_raw/compressed": COMPRESSED_T,
            "left/camera_info": INFO_T,
            "right/camera_info": INFO_T,
        }
    return {
        "left/image_raw": IMAGE_T,
        "right/image_raw": IMAGE_T,
        "left/camera_info": INFO_T,
        "right/camera_info": INFO_T,
    }


def raw_set(scene, cams, stamp: int, transport: str, **replace: object) -> list[tuple[str, object]]:
    """The four messages of one raw set of ``scene`` (images distorted by ``cams``); ``replace``: by topic."""
    from helpers.raw_rig import raw_image
    from helpers.ros2_robot import compressed_image_msg, raw_camera_info_msg

    out: list[tuple[str, object]] = []
    for side, img, cam in (("left", scene.left, cams[0]), ("right", scene.right, cams[1])):
        raw = raw_image(img, cam)
        frame_id = f"{side}_optical"
        if transport == "compressed":
            out.append((f"{side}/image_raw/compressed", compressed_image_msg(raw, stamp, frame_id, "jpeg", 95)))
        else:
            out.append((f"{side}/image_raw", image_msg(raw, stamp, frame_id)))
        out.append((f"{side}/camera_info", raw_camera_info_msg(stamp, frame_id, cam)))
    return [(name, replace.get(name, msg)) for name, msg in out]


def play_raw_rig(tmp_path, transport: str, sets: list[tuple[int, list[tuple[str, object]], bool]]):
    """Publish ``(stamp, messages, answered)`` sets to a service (ros2 source, ``rectify``, ``transport``).

    A set marked answered is awaited (its DisparityImage, by stamp) before the next is sent; the
    others are sent and passed over. Returns ``({stamp: DisparityImage}, service status)``.
    """
    config = {
        "service": {
            "out": str(tmp_path / f"run_{transport}"),
            "summary": False,
            "shutdown_timeout_s": 3.0,
            "reject_log_period_s": 0.0,  # a line for every reject: the test reads each
        },
        "source": {
            "type": "ros2",
            "rectify": True,
            "transport": transport,
            "left_image": "left/image_raw",
            "right_image": "right/image_raw",
            "depth_type": "none",
        },
        "vpp": {"enabled": False},
        "matcher": {"name": "sgbm", "max_disparity": 96},
        "queues": {"input_policy": "block", "output_policy": "block"},
        "sinks": [{"type": "ros2", "outputs": ["disparity"], "max_disparity": 96.0}],
    }
    replies: dict[int, object] = {}
    with ros2_service(config, topics=raw_rig_topics(transport), join_s=15.0) as (robot, sub, status):
        for stamp, msgs, answered in sets:
            for name, msg in msgs:
                robot.put(name, msg)
            deadline = time.monotonic() + 30.0
            while answered and stamp not in replies and time.monotonic() < deadline:
                sample = sub.try_recv()
                if sample is None:
                    time.sleep(0.01)
                    continue
                msg = TS.deserialize_cdr(sample.payload.to_bytes(), "stereo_msgs/msg/DisparityImage")
                replies[msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec] = msg
            assert not answered or stamp in replies, f"no DisparityImage for stamp {stamp} ({transport})"
    return replies, status


def answered_bad2(msg, gt: np.ndarray) -> float:
    """bad-2 (%) on the answered pixels of a DisparityImage (its cx_l = cx_r: ROS units are the project's)."""
    from vpp_service.metrics import answered_metrics

    d = msg.image.data.view("<f4").reshape(msg.image.height, msg.image.width).astype(np.float32)
    d[d < msg.min_disparity] = np.nan
    return answered_metrics(compute_metrics(d, gt))["bad2_answered"]


def rectified_bad2(scene) -> float:
    """bad-2 (%) on the answered pixels of the scene's rectified pair, matched as the service does (SGBM, no VPP)."""
    from vpp_service.frame import StereoFrame
    from vpp_service.fusion import fuse
    from vpp_service.matchers import build_matcher
    from vpp_service.metrics import answered_metrics

    res = fuse(
        StereoFrame(left=scene.left, right=scene.right), build_matcher("sgbm", {"max_disparity": 96}), depth=False
    )
    return answered_metrics(compute_metrics(res.disparity, scene.gt_disparity))["bad2_answered"]


def middlebury_scenes():
    from helpers.shared_data import need_shared
    from vpp_service.datasets import open_dataset

    return open_dataset("middlebury2006", need_shared("middlebury2005_2006_thirdsize")).select(list(RAW_SCENES))


@pytest.mark.slow
@pytest.mark.parametrize(("transport", "margin"), [("raw", 2.0), ("compressed", 3.0)])
def test_raw_rig_through_ros2_is_rectified_with_its_camera_info(tmp_path, transport, margin):
    """image_raw (or JPEG q95 image_raw/compressed) + camera_info (D, K, R, P) over rmw_zenoh, ``rectify = true``.

    bad-2 on answered pixels of every scene within ``margin`` points of its rectified pair (2 raw, 3 JPEG).
    """
    from helpers.raw_rig import rig_calibration

    scenes = middlebury_scenes()
    sets, want = [], {}
    for k, scene in enumerate(scenes):
        h, w = scene.shape
        stamp = 1_700_000_000_000_000_000 + k * 100_000_000
        sets.append((stamp, raw_set(scene, rig_calibration(w, h), stamp, transport), True))
        want[stamp] = scene
    replies, status = play_raw_rig(tmp_path, transport, sets)
    for stamp, scene in want.items():
        got, ref = answered_bad2(replies[stamp], scene.gt_disparity), rectified_bad2(scene)
        print(f"{scene.name} {transport}: bad-2 answered {got:.2f} % vs {ref:.2f} % rectified")
        assert got <= ref + margin, f"{scene.name} {transport}: bad-2 {got:.2f} % vs {ref:.2f} % rectified"
        assert replies[stamp].header.frame_id == "left_optical"
    assert status["counters"]["processed"] == len(scenes) and status["counters"]["rejected"] == 0


@pytest.mark.slow
def test_bad_raw_rig_messages_each_refused_with_a_clear_line(tmp_path, caplog):
    """A truncated JPEG, a PNG bomb, a camera_info with an all-zero P: each set refused, counted, logged; none lost."""
    from helpers.hostile import png_bomb
    from helpers.raw_rig import rig_calibration
    from helpers.ros2_robot import compressed_bytes_msg, compressed_image_msg, raw_camera_info_msg

    scene = middlebury_scenes()[0]
    h, w = scene.shape
    cams = rig_calibration(w, h)
    t0 = 1_700_000_000_000_000_000
    stamps = [t0 + k * 100_000_000 for k in range(5)]
    good_jpeg = compressed_image_msg(scene.left, stamps[1], "left_optical").data.tobytes()
    bad = {
        "truncated": compressed_bytes_msg(
            good_jpeg[: len(good_jpeg) // 2], stamps[1], "left_optical", "rgb8; jpeg compressed bgr8"
        ),
        "bomb": compressed_bytes_msg(png_bomb(20000, 20000), stamps[2], "left_optical", "rgb8; png compressed bgr8"),
        "zero_p": raw_camera_info_msg(stamps[3], "right_optical", cams[1], p=np.zeros(12)),
    }
    sets = [
        (stamps[0], raw_set(scene, cams, stamps[0], "compressed"), True),
        (
            stamps[1],
            raw_set(scene, cams, stamps[1], "compressed", **{"left/image_raw/compressed": bad["truncated"]}),
            False,
        ),
        (stamps[2], raw_set(scene, cams, stamps[2], "compressed", **{"left/image_raw/compressed": bad["bomb"]}), False),
        (stamps[3], raw_set(scene, cams, stamps[3], "compressed", **{"right/camera_info": bad["zero_p"]}), False),
        (stamps[4], raw_set(scene, cams, stamps[4], "compressed"), True),
    ]
    with caplog.at_level("WARNING"):
        replies, status = play_raw_rig(tmp_path, "compressed", sets)
    assert sorted(replies) == [stamps[0], stamps[4]]  # the good sets around the bad ones are answered
    src = status["source"]
    assert src["rejected_by"] == {"corrupt": 1, "too_large": 1, "calibration": 1}, src["rejected_by"]
    assert status["counters"]["processed"] == 2 and status["counters"]["rejected"] == 3
    lines = [r.getMessage() for r in caplog.records if "rejected input" in r.getMessage()]
    expected = [
        "/stereo/left/image_raw/compressed: corrupt: compressed image: truncated JPEG stream (no end-of-image marker)",
        "/stereo/left/image_raw/compressed: too_large: compressed image: PNG stream declares 20000x20000 = 400000000 "
        "pixels > max 8388608",
        "P is all zeros",
    ]
    for text in expected:
        assert sum(text in line for line in lines) == 1, (text, lines)
    assert len(lines) == 3, lines
    messages = src["messages"]
    assert messages["received"] == 20 and messages["used"] == 8 and messages["rejected"] == 3  # each refused alone
    # the bad sets' other messages never found partners: held or passed over, each counted once
    assert messages["received"] == sum(v for k, v in messages.items() if k != "received"), messages
