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


def test_summary_lines_in_a_log_only_when_something_changed(tmp_path):
    """Not a terminal (a journal, a file): an idle service does not repeat its summary every period."""
    import io
    import threading

    from helpers.zenoh_loopback import free_port
    from vpp_service.service.app import run_service

    data = {
        "service": {"out": str(tmp_path), "summary_period_s": 0.05},
        "zenoh": {"listen": [f"tcp/127.0.0.1:{free_port()}"]},
        "source": {"type": "zenoh"},  # nobody publishes: idle
        "matcher": {"name": "bm", "max_disparity": 32},
        "sinks": [],
    }
    stream, stop = io.StringIO(), threading.Event()

    def stop_later() -> None:  # 1.5 s (~30 summary periods) after the service has started
        while "started" not in stream.getvalue() and not stop.wait(0.05):
            pass
        stop.wait(1.5)
        stop.set()

    threading.Thread(target=stop_later, daemon=True).start()
    run_service(validate_config(data), stop, stream, banner="started")
    lines = stream.getvalue().splitlines()
    assert lines[0] == "started"
    assert len(lines) == 3, lines  # banner, one periodic line (first report), the final line; ~30 periods passed
    assert lines[1].startswith("0.0 fps") and lines[1] == lines[2]
