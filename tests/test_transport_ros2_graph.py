"""SubscriberGraph over real Zenoh sessions: subscriber tokens counted in and out, everything else ignored."""

from __future__ import annotations

import time

import pytest

from vpp_service.transport.ros2.graph import SubscriberGraph

DDS = "sensor_msgs::msg::dds_::Image_"
RIHS = "RIHS01_d31d41a9a4c4bc8eae9be757b0beed306564f7526c88ea6a4588fb9582527d47"


def token(zid: str, eid: int, kind: str = "MS", topic: str = "/stereo/left/image_rect", domain: int = 0) -> str:
    """An rmw_zenoh entity token (liveliness_utils.cpp ``Entity::Entity`` layout)."""
    return f"@ros2_lv/{domain}/{zid}/0/{eid}/{kind}/%/%stereo/cam/{topic.replace('/', '%')}/{DDS}/{RIHS}/2::,5:,:,:,,"


def wait_for(cond, timeout: float = 5.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and not cond():
        time.sleep(0.02)
    return cond()


@pytest.fixture
def graph(sessions):
    svc, _ = sessions
    g = SubscriberGraph(svc, 0)
    yield g
    g.close()


def test_counts_subscriber_tokens_in_and_out(sessions, graph):
    _, bot = sessions
    zid = str(bot.zid())
    subs = [bot.liveliness().declare_token(token(zid, eid)) for eid in (1, 2)]
    ignored = [
        bot.liveliness().declare_token(token(zid, 3, kind="MP")),  # a publisher
        bot.liveliness().declare_token(token(zid, 4, domain=1)),  # another domain
        bot.liveliness().declare_token(f"@ros2_lv/0/{zid}/0/0/NN/%/%stereo/cam"),  # a node
    ]
    key = ("/stereo/left/image_rect", DDS, RIHS)
    assert wait_for(lambda: graph.count(*key) == 2)
    time.sleep(0.2)
    assert graph.topics() == {key: 2}
    subs[0].undeclare()
    assert wait_for(lambda: graph.count(*key) == 1)
    subs[1].undeclare()
    assert wait_for(lambda: graph.topics() == {})
    for t in ignored:
        t.undeclare()


def test_tokens_alive_before_the_graph_are_counted(sessions):
    svc, bot = sessions
    tok = bot.liveliness().declare_token(token(str(bot.zid()), 1, topic="/stereo/points"))
    time.sleep(0.2)
    g = SubscriberGraph(svc, 0)
    try:
        assert wait_for(lambda: g.count("/stereo/points", DDS, RIHS) == 1)
    finally:
        g.close()
        tok.undeclare()
