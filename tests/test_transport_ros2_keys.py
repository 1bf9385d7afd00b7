"""ROS 2 graph names against the contract (docs/ros2.md): keys, type hashes, QoS strings, liveliness tokens."""

from __future__ import annotations

import pytest

from vpp_service.transport.ros2 import keys
from vpp_service.transport.ros2.messages import typestore

EXAMPLE_KEY = (
    "0/stereo/disparity/stereo_msgs::msg::dds_::DisparityImage_/"
    "RIHS01_1ec1ff6b5bace919e4544a37f2d96ead9f81783701b7b7a4d97a09325ecf2711"
)
GOLDEN_HASHES = {
    "sensor_msgs/msg/Image": "d31d41a9a4c4bc8eae9be757b0beed306564f7526c88ea6a4588fb9582527d47",
    # Jazzy's sensor_msgs/msg/CompressedImage.json (public ROS 2 clients carry the same value)
    "sensor_msgs/msg/CompressedImage": "15640771531571185e2efc8a100baf923961a4d15d5569652e6cb6691e8e371a",
    "sensor_msgs/msg/CameraInfo": "b3dfd68ff46c9d56c80fd3bd4ed22c7a4ddce8c8348f2f59c299e73118e7e275",
    "sensor_msgs/msg/PointCloud2": "9198cabf7da3796ae6fe19c4cb3bdd3525492988c70522628af5daa124bae2b5",
    "stereo_msgs/msg/DisparityImage": "1ec1ff6b5bace919e4544a37f2d96ead9f81783701b7b7a4d97a09325ecf2711",
}


def test_example_key_from_the_contract():
    topic = keys.fully_qualified("/stereo", "disparity")
    assert topic == "/stereo/disparity"
    assert keys.topic_key(0, topic, keys.DISPARITY_IMAGE) == EXAMPLE_KEY


@pytest.mark.parametrize(("ros_type", "digest"), GOLDEN_HASHES.items())
def test_type_hashes_golden_and_computed(ros_type, digest):
    assert keys.type_hash(ros_type) == f"RIHS01_{digest}"
    assert typestore().hash_rihs01(ros_type) == f"RIHS01_{digest}"


def test_dds_type_names():
    assert keys.dds_type("sensor_msgs/msg/Image") == "sensor_msgs::msg::dds_::Image_"
    assert keys.dds_type("stereo_msgs/msg/DisparityImage") == "stereo_msgs::msg::dds_::DisparityImage_"
    with pytest.raises(ValueError, match="pkg/msg/Msg"):
        keys.dds_type("sensor_msgs/Image")


@pytest.mark.parametrize(
    ("namespace", "name", "expected"),
    [
        ("/stereo", "left/image_rect", "/stereo/left/image_rect"),
        ("/stereo/", "points", "/stereo/points"),
        ("/", "points", "/points"),
        ("/stereo", "/velodyne_points", "/velodyne_points"),
    ],
)
def test_fully_qualified(namespace, name, expected):
    assert keys.fully_qualified(namespace, name) == expected


@pytest.mark.parametrize(
    ("namespace", "name"), [("stereo", "x"), ("/ste reo", "x"), ("/stereo", "a//b"), ("/stereo", "../x"), ("/s", "")]
)
def test_bad_names_rejected(namespace, name):
    with pytest.raises(ValueError, match="must look like"):
        keys.fully_qualified(namespace, name)


@pytest.mark.parametrize("domain", [-1, 233, True, 1.0])
def test_bad_domain_rejected(domain):
    with pytest.raises(ValueError, match="domain_id"):
        keys.topic_key(domain, "/a", keys.IMAGE)


def test_subscriber_wildcard_hash():
    key = keys.topic_key(3, "/stereo/left/image_rect", keys.IMAGE, "*")
    assert key == "3/stereo/left/image_rect/sensor_msgs::msg::dds_::Image_/*"


# QoS chunk of a token, derived from rmw_zenoh (ros2/rmw_zenoh, branches humble 0.1.9, jazzy 0.2.10, kilted 0.6.7,
# rolling 0.12.0 via ros2-gbp/rmw_zenoh-release): ``qos_to_keyexpr`` in rmw_zenoh_cpp/src/detail/liveliness_utils.cpp
# writes ``R:D:H,depth:dl_s,dl_ns:ls_s,ls_ns:lv,lease_s,lease_ns`` and leaves EMPTY every field equal to
# ``QoS::get().default_qos()``; qos.cpp sets those defaults (identical on all four branches):
# RMW_ZENOH_DEFAULT_RELIABILITY = RELIABLE (1), _DURABILITY = VOLATILE (2), _HISTORY = KEEP_LAST (1), _DEPTH = 42,
# deadline / lifespan / lease = RMW_DURATION_INFINITE, liveliness = AUTOMATIC. ``QoS::best_available_qos`` (run by
# rmw_create_publisher / _subscription before the token is built) turns depth 0 into 42 and the rclcpp
# "default" durations into infinite, so a QoS built by rclcpp never writes the durations.
#   rclcpp default publisher (reliable, volatile, keep last 10):  "" : "" : "" , "10" -> "::,10:,:,:,,"
#   SensorDataQoS (best effort, volatile, keep last 5):           "2": "" : "" , "5"  -> "2::,5:,:,:,,"
#   reliable, transient local, keep all, depth 0 (-> 42):         "" : "1": "2", ""   -> ":1:2,:,:,:,,"
#   rmw_zenoh's own defaults (reliable, volatile, keep last 42):  everything empty    -> "::,:,:,:,,"
QOS_GOLDEN = [
    (keys.Qos(reliability=1, durability=2, history=1, depth=10), "::,10:,:,:,,"),
    (keys.Qos(reliability=2, durability=2, history=1, depth=5), "2::,5:,:,:,,"),
    (keys.Qos(reliability=1, durability=1, history=2, depth=0), ":1:2,:,:,:,,"),
    (keys.Qos(reliability=1, durability=2, history=1, depth=42), "::,:,:,:,,"),
    (keys.Qos(reliability=2, durability=1, history=2, depth=7), "2:1:2,7:,:,:,,"),
]


@pytest.mark.parametrize(("qos", "token"), QOS_GOLDEN)
def test_qos_token_canonical(qos, token):
    assert qos.token() == token


def test_qos_named_profiles():
    assert keys.DEFAULT_PUBLISHER.token() == "::,10:,:,:,,"
    assert keys.SENSOR_DATA.token() == "2::,5:,:,:,,"
    assert keys.RELIABLE_KEEP_ALL.token() == "::2,:,:,:,,"
    with pytest.raises(ValueError, match="reliability"):
        keys.Qos(reliability=3)  # type: ignore[arg-type]


# Gid of an entity, derived from rmw_zenoh: ``Entity::Entity`` (liveliness_utils.cpp, same on the four branches)
# builds ``liveliness_keyexpr_`` from its parts and hashes that string with ``simplified_XXH3_128bits`` (a trimmed
# copy of the reference XXH3-128, seed 0, default secret: simplified_xxhash3.cpp), then ``memcpy(gid, &low64, 8);
# memcpy(gid + 8, &high64, 8)``: low 64 bits then high 64 bits, little endian on every supported host. The digests
# below were computed by compiling rmw_zenoh's simplified_xxhash3.cpp (jazzy branch) with g++ and hashing each
# string (a 10-byte, a 71-byte, a 166-byte, a 214-byte and a 329-byte input: every length path of XXH3-128).
ZID = "1f2e3d4c5b6a79880f1e2d3c4b5a6978"
RIHS_DISP = "RIHS01_1ec1ff6b5bace919e4544a37f2d96ead9f81783701b7b7a4d97a09325ecf2711"
LONG_NS = "%a_very_long_robot_namespace%with%several%levels%to%pass%two_hundred_forty_bytes"
GID_GOLDEN = [
    ("@ros2_lv/0", "4c582a11f35ae632515ffb1ffbc7bb72"),
    (f"@ros2_lv/0/{ZID}/0/0/NN/%/%stereo/vpp_stereo", "9af464a7f81f566c79c47441234f362d"),
    (
        f"@ros2_lv/0/{ZID}/3/4/MS/%/%stereo/vpp_stereo_input/%stereo%left%image_rect/"
        "sensor_msgs::msg::dds_::Image_/TypeHashNotSupported/2::,5:,:,:,,",
        "7fcd5f74a818cbdbf7f9fbff6ff62679",
    ),
    (
        f"@ros2_lv/0/{ZID}/0/1/MP/%/%stereo/vpp_stereo/%stereo%disparity/"
        f"stereo_msgs::msg::dds_::DisparityImage_/{RIHS_DISP}/::,10:,:,:,,",
        "99700b2533abe3eb8bcac6632c75f87c",
    ),
    (
        f"@ros2_lv/232/{ZID}/0/7/MP/%/{LONG_NS}/vpp_stereo/%a_very_long_robot_namespace%with%several%levels%disparity/"
        f"stereo_msgs::msg::dds_::DisparityImage_/{RIHS_DISP}/::2,:,:,:,,",
        "5bbc03d407d2f048f5c1b6998683e8a8",
    ),
]


@pytest.mark.parametrize(("token", "gid"), GID_GOLDEN)
def test_entity_gid_is_rmw_zenohs(token, gid):
    assert keys.entity_gid(token).hex() == gid


def test_tokens_byte_identical_to_rmw_zenohs():
    """Our tokens for the golden entities are the strings rmw_zenoh builds (so their gids are the golden ones)."""
    node = keys.NodeName(domain_id=0, zid=ZID, nid=0, namespace="/stereo", name="vpp_stereo")
    assert keys.node_token(node) == GID_GOLDEN[1][0]
    pub = keys.entity_token(node, 1, "MP", "/stereo/disparity", keys.DISPARITY_IMAGE, qos=keys.DEFAULT_PUBLISHER)
    assert pub == GID_GOLDEN[3][0]
    src = keys.NodeName(domain_id=0, zid=ZID, nid=3, namespace="/stereo", name="vpp_stereo_input")
    humble = keys.type_hash(keys.IMAGE, "humble")
    sub = keys.entity_token(src, 4, "MS", "/stereo/left/image_rect", keys.IMAGE, qos=keys.SENSOR_DATA, hash_=humble)
    assert sub == GID_GOLDEN[2][0]
    assert keys.entity_gid(sub).hex() == GID_GOLDEN[2][1]


# The type-hash segment per distro: the humble branch's rmw_publisher_data.cpp / rmw_subscription_data.cpp
# (``PublisherData::make`` / ``SubscriptionData::make``) put the constant "TypeHashNotSupported" in TopicInfo, hence
# in the data key (``TopicInfo::TopicInfo``: domain/topic/type/hash) and the token; jazzy, kilted and rolling put
# ``rosidl_stringify_type_hash`` of the type support's hash (RIHS01_ + 64 hex digits).
@pytest.mark.parametrize(
    ("distro", "segment"),
    [("humble", "TypeHashNotSupported"), ("jazzy", RIHS_DISP), ("kilted", RIHS_DISP), ("rolling", RIHS_DISP)],
)
def test_type_hash_per_distro(distro, segment):
    assert keys.type_hash(keys.DISPARITY_IMAGE, distro) == segment
    key = keys.topic_key(0, "/stereo/disparity", keys.DISPARITY_IMAGE, keys.type_hash(keys.DISPARITY_IMAGE, distro))
    assert key == f"0/stereo/disparity/stereo_msgs::msg::dds_::DisparityImage_/{segment}"


def test_unknown_distro_rejected():
    with pytest.raises(ValueError, match="ros_distro"):
        keys.type_hash(keys.IMAGE, "iron")


@pytest.mark.parametrize(
    ("token", "expected"),
    [
        (GID_GOLDEN[2][0], ("MS", "/stereo/left/image_rect", "sensor_msgs::msg::dds_::Image_", "TypeHashNotSupported")),
        (GID_GOLDEN[3][0], ("MP", "/stereo/disparity", "stereo_msgs::msg::dds_::DisparityImage_", RIHS_DISP)),
        (GID_GOLDEN[1][0], None),  # a node
        (GID_GOLDEN[3][0].replace("@ros2_lv/0/", "@ros2_lv/1/"), None),  # another domain
        (GID_GOLDEN[3][0].replace("/MP/", "/SS/"), None),  # a service
    ],
)
def test_parse_entity_token(token, expected):
    ent = keys.parse_entity_token(token, 0)
    assert (None if ent is None else (ent.kind, ent.topic, ent.dds_type, ent.type_hash)) == expected


def test_liveliness_tokens():
    node = keys.NodeName(domain_id=0, zid="abc123", nid=0, namespace="/stereo", name="vpp_service")
    assert keys.node_token(node) == "@ros2_lv/0/abc123/0/0/NN/%/%stereo/vpp_service"
    pub = keys.entity_token(node, 5, "MP", "/stereo/disparity", keys.DISPARITY_IMAGE, qos=keys.DEFAULT_PUBLISHER)
    assert pub == (
        "@ros2_lv/0/abc123/0/5/MP/%/%stereo/vpp_service/%stereo%disparity/"
        "stereo_msgs::msg::dds_::DisparityImage_/RIHS01_1ec1ff6b5bace919e4544a37f2d96ead9f81783701b7b7a4d97a09325ecf2711/"
        "::,10:,:,:,,"
    )
    root = keys.NodeName(domain_id=7, zid="z", nid=2, namespace="/", name="n", enclave="/secure")
    assert keys.node_token(root) == "@ros2_lv/7/z/2/2/NN/%secure/%/n"
    with pytest.raises(ValueError, match="kind"):
        keys.entity_token(node, 1, "SS", "/a", keys.IMAGE, qos=keys.SENSOR_DATA)  # type: ignore[arg-type]


def test_mangle():
    assert keys.mangle("") == "%"
    assert keys.mangle("/a/b") == "%a%b"
