"""Sink hooks the service asks instead of reading option names: needs_depth, needs_session."""

from __future__ import annotations

import pytest

from vpp_service.sinks import SINKS
from vpp_service.sinks.base import Sink, parse_sink_options


@pytest.mark.parametrize(
    ("name", "options", "expected"),
    [
        ("zenoh", {"outputs": ["disparity"]}, False),
        ("zenoh", {"outputs": ["disparity", "depth"]}, True),
        ("zenoh", {"outputs": ["left_vpp"]}, False),
        ("files", {"dir": "x"}, False),
        ("files", {"dir": "x", "depth": True}, True),
        ("record", {"dir": "x"}, False),
        ("rerun", {}, True),
    ],
)
def test_each_sink_says_whether_it_reads_depth(name, options, expected):
    cls = SINKS.get(name)
    assert cls.needs_depth(parse_sink_options(name, options)) is expected


def test_base_sink_reads_depth_unless_it_says_otherwise():
    assert Sink.needs_depth(None) is True


@pytest.mark.parametrize(("name", "expected"), [("zenoh", True), ("rerun", False), ("files", False), ("record", False)])
def test_needs_session(name, expected):
    assert SINKS.get(name).needs_session is expected
