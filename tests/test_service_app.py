"""build_pipeline asks the plugins (needs_depth) instead of reading their options."""

from __future__ import annotations

import copy

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
