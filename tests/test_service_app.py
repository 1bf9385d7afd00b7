"""build_pipeline asks the plugins (needs_depth) instead of reading their options."""

from __future__ import annotations

import copy
import json
import time

import pytest

from vpp_service.service.app import build_pipeline
from vpp_service.service.config import DEFAULT_CONFIG, validate_config


def config(sinks: list[dict]) -> dict:
    data = copy.deepcopy(DEFAULT_CONFIG)
    data["sinks"] = sinks
    return data


@pytest.mark.parametrize(
    ("sinks", "depth"),
    [
        ([], False),
        ([{"type": "zenoh", "outputs": ["disparity"]}], False),
        ([{"type": "zenoh", "outputs": ["disparity", "depth"]}], True),
        ([{"type": "zenoh", "outputs": ["disparity"]}, {"type": "record", "dir": "REC"}], False),
        ([{"type": "zenoh", "outputs": ["disparity"]}, {"type": "files", "dir": "F", "depth": True}], True),
        ([{"type": "rerun", "path": "x.rrd"}], True),
    ],
)
def test_metric_depth_only_when_a_sink_reads_it(tmp_path, sinks, depth):
    for s in sinks:
        if "dir" in s:
            s["dir"] = str(tmp_path / s["dir"])
    pipe = build_pipeline(validate_config(config(sinks)), session=None)  # built, not opened
    assert pipe.process.depth is depth
    assert [type(s).__name__ for s in pipe.sinks] == [f"{s['type'].capitalize()}Sink" for s in sinks]


def test_session_drops_messages_over_its_max_message_size(zenoh_endpoint):
    import zenoh

    from helpers.zenoh_loopback import zenoh_test_config
    from vpp_service.service.app import zenoh_config
    from vpp_service.service.config import ZenohSection

    section = ZenohSection(listen=[zenoh_endpoint], max_message_mb=1.0)
    conf = zenoh_config(section)
    assert json.loads(conf.get_json("transport/link/rx/max_message_size")) == (1 << 20) + 64 * 1024
    got: list[int] = []
    with zenoh.open(conf) as svc, zenoh.open(zenoh_test_config(connect=[zenoh_endpoint])) as peer:
        svc.declare_subscriber("t/x", lambda s: got.append(len(s.payload)))
        time.sleep(0.5)
        pub = peer.declare_publisher("t/x", congestion_control=zenoh.CongestionControl.BLOCK)
        pub.put(bytes(4 << 20))  # over the cap: Zenoh never assembles it
        pub.put(bytes(1000))  # the link survives: the next message arrives
        deadline = time.monotonic() + 5
        while not got and time.monotonic() < deadline:
            time.sleep(0.01)
        time.sleep(0.2)
    assert got == [1000]


def test_max_message_mb_is_validated():
    from vpp_service.service.config import ZenohSection

    with pytest.raises(ValueError, match="max_message_mb"):
        ZenohSection(max_message_mb=0)
