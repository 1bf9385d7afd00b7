"""StereoAssembler: stereo sync (exact / approximate), depth matching and waiting, refusals counted by cause."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.ros2_robot import TS, camera_info_msg, cloud_msg, image_msg, raw_camera_info_msg, tf_message
from vpp_service.settings import SettingsError, from_mapping
from vpp_service.sources.ros2_assembler import StereoAssembler, StereoTopics

H, W, F, B = 6, 8, 100.0, 0.1


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def cdr(msg: object, ros_type: str) -> bytes:
    return bytes(TS.serialize_cdr(msg, ros_type, little_endian=True))


def pair(stamp: int, *, encoding: str = "rgb8", width: int = W, doffs: float = 2.0) -> dict[str, bytes]:
    rng = np.random.default_rng(stamp % 1000)
    img = rng.integers(0, 256, (H, width, 3), dtype=np.uint8)
    if encoding == "mono8":
        img = img[:, :, 0].copy()
    img_t, info_t = "sensor_msgs/msg/Image", "sensor_msgs/msg/CameraInfo"
    return {
        "left_image": cdr(image_msg(img, stamp, "left", encoding), img_t),
        "right_image": cdr(image_msg(img, stamp, "right", encoding), img_t),
        "left_info": cdr(camera_info_msg(stamp, "left", (W, H), f=F, cx=3.5, cy=2.5, tx=0.0), info_t),
        "right_info": cdr(camera_info_msg(stamp, "right", (W, H), f=F, cx=3.5 + doffs, cy=2.5, tx=-F * B), info_t),
    }


def cloud(stamp: int, z: float = 2.0) -> bytes:
    xyz = np.array([[0.0, 0.0, z], [0.0, 0.0, -1.0], [5.0, 0.0, 1.0]], np.float32)
    return cdr(cloud_msg(xyz, stamp, "left"), "sensor_msgs/msg/PointCloud2")


def make(clock: Clock | None = None, **opts: object) -> tuple[StereoAssembler, list[str]]:
    rejects: list[str] = []
    topics = from_mapping(StereoTopics, opts, "source")
    return StereoAssembler(topics, "r", rejects.append, clock or Clock()), rejects


def feed(asm: StereoAssembler, parts: dict[str, bytes]) -> list:
    out = []
    for role, payload in parts.items():
        out += asm.add(role, payload)
    return out


def test_exact_sync_with_cloud_and_calibration():
    asm, rejects = make()
    assert asm.add("depth", cloud(1_000)) == []
    frames = feed(asm, pair(1_000))
    assert len(frames) == 1 and not rejects
    f = frames[0]
    assert f.calib.f == F and f.calib.baseline == pytest.approx(B) and f.calib.doffs == 2.0 and f.calib.cx == 3.5
    assert f.stamp_ns == 1_000 and f.meta["ros"] == {"stamp_ns": 1_000, "frame_id": "left"} and f.seq == 1
    assert f.left.shape == (H, W, 3) and "decode" in f.meta["timing_ms"]
    # (0, 0, 2) projects on the principal point (3.5, 2.5) -> pixel rint: (2, 4)
    assert f.sensor_depth[2, 4] == 2.0 and np.isfinite(f.sensor_depth).sum() == 1
    st = asm.stats()
    assert (st["cloud_behind"], st["cloud_outside"], st["cloud_points"], st["no_depth"]) == (1, 1, 1, 0)


def test_cloud_frames_are_lidar_like_and_their_see_through_points_are_filtered():
    from vpp_service.fusion import DEFAULT_DEPTH_FILTER, sparse_disparity

    # near returns on pixels (2, 4) and (2, 6), and a far one between them (2, 5) that the camera cannot see
    xyz = np.array([[0.0, 0.0, 1.0], [2.5 * 1.0 / F, 0.0, 1.0], [1.5 * 4.0 / F, 0.0, 4.0]], np.float32)
    asm, _ = make()
    asm.add("depth", cdr(cloud_msg(xyz, 1_000, "left"), "sensor_msgs/msg/PointCloud2"))
    (f,) = feed(asm, pair(1_000))
    assert f.meta["lidar_like"] is True and np.isfinite(f.sensor_depth).sum() == 3  # disparities 8, 8, 0.5
    assert DEFAULT_DEPTH_FILTER.applies(f.meta)
    kept, dropped = DEFAULT_DEPTH_FILTER(sparse_disparity(f))
    assert dropped == 1 and np.isfinite(kept[2, 4]) and np.isfinite(kept[2, 6]) and not np.isfinite(kept[2, 5])


def test_exact_sync_needs_equal_stamps():
    asm, _ = make(depth_type="none")
    p1, p2 = pair(1_000), pair(1_001)
    assert asm.add("left_image", p1["left_image"]) == []
    assert asm.add("left_info", p1["left_info"]) == []
    assert asm.add("right_image", p2["right_image"]) == []
    assert asm.add("right_info", p2["right_info"]) == []
    assert asm.add("right_image", p1["right_image"]) == []
    frames = asm.add("right_info", p1["right_info"])
    assert len(frames) == 1 and frames[0].sensor_depth is None and asm.stats()["no_depth"] == 1
    assert frames[0].meta["lidar_like"] is False


def test_approximate_sync_within_tolerance():
    asm, _ = make(depth_type="none", sync="approximate", sync_tolerance_ms=1.0)
    p1, p2 = pair(1_000_000), pair(1_500_000)
    parts = {"left_image": p1["left_image"], "left_info": p1["left_info"]}
    parts |= {"right_image": p2["right_image"], "right_info": p2["right_info"]}
    frames = feed(asm, parts)
    assert len(frames) == 1


def test_depth_nearest_within_tolerance_and_wait():
    clock = Clock()
    asm, _ = make(clock, depth_tolerance_ms=10.0, depth_wait_ms=100.0)
    assert feed(asm, pair(100_000_000)) == []  # waits for its depth
    clock.t = 0.05
    assert asm.expire() == []
    assert asm.add("depth", cloud(95_000_000, z=3.0)) == []  # within 10 ms, but a nearer one may still come
    clock.t = 0.1  # the wait is over: the nearest there is
    frames = asm.expire()
    assert len(frames) == 1 and frames[0].sensor_depth[2, 4] == 3.0
    assert feed(asm, pair(200_000_000)) == []
    clock.t = 0.25  # 150 ms later: no depth came
    frames = asm.expire()
    assert len(frames) == 1 and frames[0].sensor_depth is None
    assert asm.stats()["no_depth"] == 1


@pytest.mark.parametrize("own_first", [True, False])
def test_depth_choice_waits_for_the_sets_own_message(own_first):
    # a set 30 ms after the last one: the last set's cloud is within the tolerance, but the set's own
    # cloud (same stamp) is nearer; whether it comes before or after the images, the set takes it
    asm, _ = make(depth_tolerance_ms=50.0, depth_wait_ms=10_000.0)
    assert len(feed(asm, {"depth": cloud(100_000_000, z=3.0)} | pair(100_000_000))) == 1
    parts = pair(130_000_000)
    own = {"depth": cloud(130_000_000, z=5.0)}
    frames = feed(asm, own | parts) if own_first else feed(asm, parts) + feed(asm, own)
    assert len(frames) == 1 and frames[0].sensor_depth[2, 4] == 5.0


def test_later_depth_decides_the_nearest():
    asm, _ = make(depth_tolerance_ms=10.0, depth_wait_ms=10_000.0)
    assert feed(asm, pair(100_000_000)) == []
    assert asm.add("depth", cloud(96_000_000, z=3.0)) == []
    frames = asm.add("depth", cloud(103_000_000, z=4.0))  # after the pair: nothing nearer can come now
    assert len(frames) == 1 and frames[0].sensor_depth[2, 4] == 4.0


def test_later_depth_ends_the_wait():
    asm, _ = make(depth_tolerance_ms=10.0, depth_wait_ms=10_000.0)
    assert feed(asm, pair(100_000_000)) == []
    frames = asm.add("depth", cloud(300_000_000))  # newer than the pair + tolerance: none will match
    assert len(frames) == 1 and frames[0].sensor_depth is None


def test_depth_image_16uc1():
    asm, rejects = make(depth_type="image")
    mm = np.zeros((H, W), np.uint16)
    mm[1, 2] = 1500
    depth = cdr(image_msg(mm, 5, "left", "16UC1"), "sensor_msgs/msg/Image")
    asm.add("depth", depth)
    frames = feed(asm, pair(5))
    assert not rejects and frames[0].sensor_depth[1, 2] == pytest.approx(1.5)
    assert np.isfinite(frames[0].sensor_depth).sum() == 1


def test_refusals_counted_by_cause():
    asm, rejects = make(depth_type="none")
    asm.add("left_image", b"\x00\x01\x00\x00\x01")
    feed(asm, pair(7, encoding="bgr8") | {"left_image": pair(7, encoding="mono8")["left_image"]})  # shape mismatch
    bad = pair(8)
    bad["left_image"] = cdr(image_msg(np.zeros((H, W), np.uint16), 8, "left", "mono12"), "sensor_msgs/msg/Image")
    feed(asm, bad)
    feed(asm, pair(9, width=W + 2))  # camera_info says 8 wide
    assert asm.rejected_by == {"cdr": 1, "shape": 2, "encoding": 1}
    assert any("mono12" in r for r in rejects)


def test_mono_frames():
    asm, _ = make(depth_type="none")
    frames = feed(asm, pair(3, encoding="mono8"))
    assert frames[0].left.shape == (H, W)


def test_compressed_transport_topics_types_and_refusals():
    from helpers.ros2_robot import compressed_bytes_msg, compressed_image_msg

    asm, rejects = make(depth_type="image", transport="compressed", left_image="left/image_raw")
    t = asm.topics
    assert t.topic("left_image") == "/stereo/left/image_raw/compressed"
    assert t.topic("right_image") == "/stereo/right/image_rect/compressed"
    assert t.ros_type("left_image") == t.ros_type("right_image") == "sensor_msgs/msg/CompressedImage"
    assert (
        t.topic("left_info") == "/stereo/left/camera_info" and t.ros_type("left_info") == "sensor_msgs/msg/CameraInfo"
    )
    assert t.topic("depth") == "/stereo/points" and t.ros_type("depth") == "sensor_msgs/msg/Image"  # depth stays raw
    rng = np.random.default_rng(3)
    img = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
    comp_t = "sensor_msgs/msg/CompressedImage"

    def views(stamp: int, left: object | None = None) -> dict[str, bytes]:
        parts = pair(stamp)
        parts["left_image"] = cdr(left or compressed_image_msg(img, stamp, "left", "png"), comp_t)
        parts["right_image"] = cdr(compressed_image_msg(img, stamp, "right", "png"), comp_t)
        return parts

    depth = cdr(image_msg(np.full((H, W), 1.5, np.float32), 1, "left", "32FC1"), "sensor_msgs/msg/Image")
    asm.add("depth", depth)
    (f,) = feed(asm, views(1))
    np.testing.assert_array_equal(f.left, img)
    np.testing.assert_array_equal(f.right, img)
    jpeg = compressed_image_msg(img, 2, "left", "jpeg")
    cut = compressed_bytes_msg(jpeg.data.tobytes()[:-30], 2, "left", jpeg.format)
    assert feed(asm, views(2, cut)) == []
    assert asm.rejected_by == {"corrupt": 1}
    assert rejects == [
        "/stereo/left/image_raw/compressed: corrupt: compressed image: truncated JPEG stream (no end-of-image marker)"
    ]
    asm.add("depth", cdr(image_msg(np.full((H, W), 1.5, np.float32), 3, "left", "32FC1"), "sensor_msgs/msg/Image"))
    assert len(feed(asm, views(3))) == 1  # nothing else lost


def tf_static(*entries) -> bytes:
    return cdr(tf_message(list(entries)), "tf2_msgs/msg/TFMessage")


#: The cloud's frame 'lidar' sits 0.5 m behind the left camera (its x y z axes along the camera's).
LIDAR_BEHIND = ("left", "lidar", (0.0, 0.0, -0.5), (0.0, 0.0, 0.0, 1.0))


def test_cloud_transform_from_tf_static():
    asm, rejects = make()
    assert asm.topics.roles()[-1] == "tf_static" and asm.topics.topic("tf_static") == "/tf_static"
    assert asm.add("tf_static", tf_static(LIDAR_BEHIND)) == []
    xyz = np.array([[0.0, 0.0, 2.5]], np.float32)  # 2.5 m ahead of the LiDAR = 2 m ahead of the camera
    asm.add("depth", cdr(cloud_msg(xyz, 1_000, "lidar"), "sensor_msgs/msg/PointCloud2"))
    (f,) = feed(asm, pair(1_000))
    assert not rejects and f.sensor_depth[2, 4] == pytest.approx(2.0) and np.isfinite(f.sensor_depth).sum() == 1
    assert asm.stats()["tf_messages"] == 1 and asm.stats()["messages"]["used"] == 6  # tf + 4 + cloud


def test_cloud_without_a_transform_is_refused_and_the_frame_goes_on():
    asm, rejects = make()
    xyz = np.array([[0.0, 0.0, 2.5]], np.float32)
    asm.add("depth", cdr(cloud_msg(xyz, 1_000, "lidar"), "sensor_msgs/msg/PointCloud2"))
    (f,) = feed(asm, pair(1_000))
    assert f.sensor_depth is None and f.meta["lidar_like"] is False and asm.stats()["no_depth"] == 1
    assert asm.rejected_by == {"tf": 1} and "no static transform chain from 'lidar' to 'left'" in rejects[0]
    m = asm.stats()["messages"]
    assert (m["received"], m["used"], m["rejected"], m["unmatched"]) == (5, 4, 1, 0)


def test_configured_extrinsic_wins_and_needs_no_tf():
    shift = [[1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 1.0, 1.0], [0, 0, 0, 1.0]]  # z + 1 m
    asm, _ = make(lidar_to_left=shift)
    assert "tf_static" not in asm.topics.roles()
    asm.add(
        "depth", cdr(cloud_msg(np.array([[0.0, 0.0, 1.0]], np.float32), 1_000, "lidar"), "sensor_msgs/msg/PointCloud2")
    )
    (f,) = feed(asm, pair(1_000))
    assert f.sensor_depth[2, 4] == pytest.approx(2.0)


def test_bad_tf_message_refused():
    asm, _ = make()
    asm.add("tf_static", tf_static(("left", "lidar", (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 0.0))))
    assert asm.rejected_by == {"tf": 1} and asm.stats()["messages"]["rejected"] == 1


@pytest.mark.parametrize(
    "opts",
    [
        {"left_image": "bad name"},
        {"namespace": "stereo"},
        {"lidar_to_left": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]},
        {"sync_queue_size": 0},
        {"depth_tolerance_ms": -1.0},
        {"max_message_mb": 0.0},
        {"depth_type": "laser"},
        {"transport": "theora"},
    ],
)
def test_bad_options(opts):
    with pytest.raises(SettingsError):
        from_mapping(StereoTopics, opts, "source")


def raw_info(stamp: int, frame_id: str, info, **changes: object) -> bytes:
    """A raw camera's CameraInfo (``K``, ``D``, ``R``, ``P`` of ``info``), fields replaced by ``changes``, as CDR."""
    return cdr(raw_camera_info_msg(stamp, frame_id, info, **changes), "sensor_msgs/msg/CameraInfo")


def test_raw_images_are_rectified_with_the_camera_info_as_stereo_image_proc_does():
    """image_raw + camera_info (D, K, R, P) of a real scene: answers as on the rectified pair."""
    from helpers.raw_rig import raw_image, rig_calibration
    from helpers.shared_data import need_shared
    from vpp_service.datasets import open_dataset
    from vpp_service.fusion import fuse
    from vpp_service.matchers import build_matcher

    scene = open_dataset("middlebury2006", need_shared("middlebury2005_2006_thirdsize")).select(["Moebius"])[0]
    h, w = scene.shape
    left, right = rig_calibration(w, h)
    img_t = "sensor_msgs/msg/Image"
    asm, rejects = make(rectify=True, depth_type="none")
    parts = {
        "left_image": cdr(image_msg(raw_image(scene.left, left), 5_000, "left"), img_t),
        "right_image": cdr(image_msg(raw_image(scene.right, right), 5_000, "right"), img_t),
        "left_info": raw_info(5_000, "left", left),
        "right_info": raw_info(5_000, "right", right),
    }
    frames = feed(asm, parts)
    assert len(frames) == 1 and not rejects
    f = frames[0]
    assert f.calib.f == left.p[0, 0] and f.calib.baseline == pytest.approx(-right.p[0, 3] / right.p[0, 0])
    matcher = build_matcher("sgbm", {"max_disparity": 96})
    got = fuse(f.with_(gt_disparity=scene.gt_disparity), matcher).metrics["bad2_answered"]
    want = fuse(scene, matcher).metrics["bad2_answered"]
    assert got <= want + 2.0, f"bad-2 {got:.2f} % image_raw vs {want:.2f} % rectified"
    assert asm._rectifier is not None
    maps = asm._rectifier[1]
    parts2 = {
        "left_image": cdr(image_msg(raw_image(scene.left, left), 6_000, "left"), img_t),
        "right_image": cdr(image_msg(raw_image(scene.right, right), 6_000, "right"), img_t),
        "left_info": raw_info(6_000, "left", left),
        "right_info": raw_info(6_000, "right", right),
    }
    assert len(feed(asm, parts2)) == 1 and asm._rectifier[1] is maps  # the maps are built once per calibration


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"p": np.zeros(12)}, "P is all zeros"),
        ({"k": np.array([np.nan, 0, 3.5, 0, 100.0, 2.5, 0, 0, 1])}, "K holds a NaN"),
    ],
)
def test_a_raw_camera_info_that_cannot_rectify_refuses_only_its_set(changes, message):
    from helpers.raw_rig import rig_calibration

    left, right = rig_calibration(W, H)
    asm, rejects = make(rectify=True, depth_type="none")
    img = np.zeros((H, W), np.uint8)
    img_t = "sensor_msgs/msg/Image"

    def parts(stamp: int, **right_changes: object) -> dict[str, bytes]:
        return {
            "left_image": cdr(image_msg(img, stamp, "left"), img_t),
            "right_image": cdr(image_msg(img, stamp, "right"), img_t),
            "left_info": raw_info(stamp, "left", left),
            "right_info": raw_info(stamp, "right", right, **right_changes),
        }

    bad, good = parts(1_000, **changes), parts(2_000)
    assert feed(asm, bad) == []
    assert len(rejects) == 1 and message in rejects[0] and "right/camera_info" in rejects[0]
    assert len(feed(asm, good)) == 1  # nothing else lost
