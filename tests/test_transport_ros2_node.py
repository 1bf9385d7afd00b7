"""RosNode over real Zenoh sessions: gids, QoS -> Zenoh options, subscriber tokens per distro, ROS-subscriber liveness.

The "ROS side" here is a second session that declares keys and tokens by hand as rmw_zenoh does
(tests/helpers/ros2_robot.py's contract), never through vpp_service's ROS code.
"""

from __future__ import annotations

import time

import pytest
import xxhash
import zenoh

from helpers.zenoh_loopback import collect
from vpp_service.transport.ros2 import attachment, keys
from vpp_service.transport.ros2.node import RosNode

DISP = "stereo_msgs/msg/DisparityImage"
DDS_DISP = "stereo_msgs::msg::dds_::DisparityImage_"
RIHS_DISP = "RIHS01_1ec1ff6b5bace919e4544a37f2d96ead9f81783701b7b7a4d97a09325ecf2711"
HASHES = {"humble": "TypeHashNotSupported", "jazzy": RIHS_DISP}


def sub_token(zid: str, eid: int, topic: str, hash_: str, domain: int = 0) -> str:
    """A subscriber token as rmw_zenoh writes it (node /stereo/viewer, SensorDataQoS)."""
    return (
        f"@ros2_lv/{domain}/{zid}/0/{eid}/MS/%/%stereo/viewer/{topic.replace('/', '%')}/{DDS_DISP}/{hash_}/2::,5:,:,:,,"
    )


def wait_until(cond, timeout: float = 5.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(0.02)
    return cond()


@pytest.fixture
def node(sessions):
    svc, _ = sessions
    n = RosNode(svc, 0, "/stereo", "vpp_stereo")
    n.open()
    yield n
    n.close()


def test_gid_in_attachment_is_rmw_zenohs_hash_of_the_graph_token(sessions, node):
    """The gid a subscriber reads per message is XXH3-128 (low, high; little endian) of the token on the graph."""
    _, bot = sessions
    seen: list[str] = []
    graph = bot.liveliness().declare_subscriber("@ros2_lv/0/**", lambda s: seen.append(str(s.key_expr)), history=True)
    sub = bot.declare_subscriber(f"0/stereo/disparity/{DDS_DISP}/{RIHS_DISP}", zenoh.handlers.FifoChannel(8))
    pub = node.publisher("/stereo/disparity", DISP)
    assert wait_until(lambda: any("/MP/" in t for t in seen))
    time.sleep(0.2)
    pub.put(b"\x00\x01\x00\x00")
    (sample,) = collect(sub, 1)
    graph.undeclare()
    (token,) = [t for t in seen if "/MP/" in t]
    assert token == pub.token_key and token.endswith("/::,10:,:,:,,")
    digest = xxhash.xxh3_128_intdigest(token.encode())
    expected = (digest & (2**64 - 1)).to_bytes(8, "little") + (digest >> 64).to_bytes(8, "little")
    assert attachment.decode(sample.attachment.to_bytes())[0].gid == expected == pub.gid


@pytest.mark.parametrize(
    ("qos", "congestion"),
    [
        (keys.DEFAULT_PUBLISHER, zenoh.CongestionControl.DROP),  # reliable + keep last: DROP
        (keys.RELIABLE_KEEP_ALL, zenoh.CongestionControl.BLOCK),  # reliable + keep all: BLOCK
        (keys.Qos(reliability=2, history=2), zenoh.CongestionControl.DROP),  # best effort: DROP
    ],
)
def test_publisher_qos_maps_as_rmw_zenoh(sessions, node, qos, congestion):
    """rmw_zenoh PublisherData::make: congestion control BLOCK only for reliable + keep all."""
    _, bot = sessions
    sub = bot.declare_subscriber(f"0/stereo/disparity/{DDS_DISP}/{RIHS_DISP}", zenoh.handlers.FifoChannel(8))
    pub = node.publisher("/stereo/disparity", DISP, qos)
    time.sleep(0.3)
    pub.put(b"\x00\x01\x00\x00")
    (sample,) = collect(sub, 1)
    assert sample.congestion_control == congestion
    assert pub.token_key.endswith(f"/{qos.token()}")


def test_transient_local_publisher_refused(node):
    with pytest.raises(ValueError, match="transient-local"):
        node.publisher("/stereo/disparity", DISP, keys.Qos(durability=1))


@pytest.mark.parametrize("distro", ["humble", "jazzy"])
def test_keys_and_tokens_follow_the_distro(sessions, distro):
    svc, bot = sessions
    seen: list[str] = []
    graph = bot.liveliness().declare_subscriber("@ros2_lv/0/**", lambda s: seen.append(str(s.key_expr)), history=True)
    n = RosNode(svc, 0, "/stereo", "vpp", distro=distro)
    n.open()
    try:
        pub = n.publisher("/stereo/disparity", DISP)
        got: list[zenoh.Sample] = []
        n.subscribe("/stereo/in", DISP, got.append)
        assert wait_until(lambda: sum("/MP/" in t or "/MS/" in t for t in seen) == 2)
        # the source side still receives publishers of either distro
        for h in HASHES.values():
            bot.put(f"0/stereo/in/{DDS_DISP}/{h}", b"x")
        assert wait_until(lambda: len(got) == 2)
    finally:
        n.close()
        graph.undeclare()
    assert pub.key == f"0/stereo/disparity/{DDS_DISP}/{HASHES[distro]}"
    assert all(t.split("/")[11] == HASHES[distro] for t in seen if "/MP/" in t or "/MS/" in t)


def test_live_only_for_a_ros_subscriber_token_of_the_same_hash(sessions, node):
    """Wildcard captures and plain Zenoh subscribers do not wake a lazy output; a subscriber token does."""
    _, bot = sessions
    zid = str(bot.zid())
    pub = node.publisher("/stereo/disparity", DISP)
    capture = bot.declare_subscriber("0/stereo/**", lambda s: None)
    plain = bot.declare_subscriber(pub.key, lambda s: None)
    assert wait_until(lambda: pub.matching)  # Zenoh matching: true for both
    time.sleep(0.3)
    assert not pub.live
    humble = bot.liveliness().declare_token(sub_token(zid, 1, "/stereo/disparity", HASHES["humble"]))
    other = bot.liveliness().declare_token(sub_token(zid, 2, "/stereo/depth", RIHS_DISP))
    time.sleep(0.3)
    assert not pub.live  # another hash (would not receive) or another topic
    jazzy = bot.liveliness().declare_token(sub_token(zid, 3, "/stereo/disparity", RIHS_DISP))
    assert wait_until(lambda: pub.live)
    jazzy.undeclare()
    assert wait_until(lambda: not pub.live)
    for e in (humble, other, capture, plain):
        e.undeclare()


def test_live_sees_tokens_declared_before_the_publisher(sessions, node):
    _, bot = sessions
    tok = bot.liveliness().declare_token(sub_token(str(bot.zid()), 1, "/stereo/disparity", RIHS_DISP))
    time.sleep(0.2)
    pub = node.publisher("/stereo/disparity", DISP)
    assert wait_until(lambda: pub.live)
    tok.undeclare()
