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


def test_qos_token_strings():
    assert keys.SENSOR_DATA.token() == "2:2:1,5:,:,:,,"
    assert keys.DEFAULT_PUBLISHER.token() == "1:2:1,10:,:,:,,"
    with pytest.raises(ValueError, match="reliability"):
        keys.Qos(reliability=3)  # type: ignore[arg-type]


def test_liveliness_tokens():
    node = keys.NodeName(domain_id=0, zid="abc123", nid=0, namespace="/stereo", name="vpp_service")
    assert keys.node_token(node) == "@ros2_lv/0/abc123/0/0/NN/%/%stereo/vpp_service"
    pub = keys.entity_token(node, 5, "MP", "/stereo/disparity", keys.DISPARITY_IMAGE, qos=keys.DEFAULT_PUBLISHER)
    assert pub == (
        "@ros2_lv/0/abc123/0/5/MP/%/%stereo/vpp_service/%stereo%disparity/"
        "stereo_msgs::msg::dds_::DisparityImage_/RIHS01_1ec1ff6b5bace919e4544a37f2d96ead9f81783701b7b7a4d97a09325ecf2711/"
        "1:2:1,10:,:,:,,"
    )
    root = keys.NodeName(domain_id=7, zid="z", nid=2, namespace="/", name="n", enclave="/secure")
    assert keys.node_token(root) == "@ros2_lv/7/z/2/2/NN/%secure/%/n"
    with pytest.raises(ValueError, match="kind"):
        keys.entity_token(node, 1, "SS", "/a", keys.IMAGE, qos=keys.SENSOR_DATA)  # type: ignore[arg-type]


def test_mangle():
    assert keys.mangle("") == "%"
    assert keys.mangle("/a/b") == "%a%b"
