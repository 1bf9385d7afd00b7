"""The ``rerun`` sink's output on its own: the recording stream, the .rrd file and its rotation, a viewer's life."""

from __future__ import annotations

import socket
import time
from collections import Counter

import numpy as np
import pytest
from rerun.chunk import RrdReader

from helpers.frames import make_frame
from helpers.rerun_rrd import read_rrd
from vpp_service.frame import FusionResult
from vpp_service.sinks.rerun import RerunSinkOptions
from vpp_service.sinks.rerun_log import RerunLayout, RerunParts, parts_from_result
from vpp_service.sinks.rerun_output import PROBE_INTERVAL_S, RerunOutput, reachable
from vpp_service.sinks.rotation import rotated_paths

RIG = "rigO"


def parts(seq: int, h: int = 48, w: int = 64) -> RerunParts:
    frame = make_frame(h=h, w=w, seed=seq).with_(seq=seq, rig=RIG)
    disp = np.random.default_rng(seq).uniform(2.0, 30.0, (h, w)).astype(np.float32)
    return parts_from_result(FusionResult(frame, disp))


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def output(**opts) -> tuple[RerunOutput, Counter[str]]:
    counts: Counter[str] = Counter()
    layout = RerunLayout(jpeg_quality=0, depth_range=(0.5, 20.0))
    return RerunOutput(RerunSinkOptions(**opts), layout, RIG, lambda name: counts.update([name])), counts


def test_the_stream_exists_only_once_opened():
    out, _ = output(mode="connect")
    assert not out.opened
    with pytest.raises(RuntimeError, match="not open"):
        out.recording()
    out.open("vpp-service-test", "rec-1")
    assert out.opened and out.recording() is out.recording()


def test_save_opens_the_file_and_sends_every_frame(tmp_path):
    path = tmp_path / "o.rrd"
    out, counts = output(mode="save", path=str(path), max_mb=0)
    out.open("vpp-service-test", "rec-1")
    assert path.exists()
    assert all(out.send(parts(seq)) for seq in range(3))
    out.flush_and_disconnect(time.monotonic() + 5)
    assert counts == Counter() and read_rrd(path)[f"/{RIG}/left"]["seq"] == [0, 1, 2]


def test_save_to_a_missing_folder_is_refused_at_open(tmp_path):
    out, _ = output(mode="save", path=str(tmp_path / "nope" / "o.rrd"))
    with pytest.raises(FileNotFoundError, match="does not exist"):
        out.open("vpp-service-test", "rec-1")


def test_save_rotation_is_counted_and_every_part_is_a_complete_recording(tmp_path):
    path = tmp_path / "o.rrd"
    out, counts = output(mode="save", path=str(path), max_mb=0.05, max_files=2)
    out.open("vpp-service-test", "rec-1")
    for seq in range(12):
        assert out.send(parts(seq, 96, 128))
    out.flush_and_disconnect(time.monotonic() + 5)
    assert counts["rotations"] >= 2 and set(counts) == {"rotations"}
    files = rotated_paths(path, 2)
    assert all(f.exists() for f in files) and len(list(tmp_path.iterdir())) == 2
    for f in files:
        assert len(RrdReader(f).recordings()) == 1 and len(RrdReader(f).blueprints()) == 1
    assert read_rrd(files[0])[f"/{RIG}/left"]["seq"][-1] == 11


def test_a_viewer_that_appears_later_is_reconnected_and_counted():
    port = free_port()
    url = f"rerun+http://127.0.0.1:{port}/proxy"
    out, counts = output(mode="connect", url=url)
    out.open("vpp-service-test", "rec-1")
    out.attach()  # no viewer yet: a warning, not an error
    assert not out.send(parts(0)) and not out.send(parts(1))  # undelivered, said by the sink
    server, _ = output(mode="serve", grpc_port=port)  # a real server stands in for the viewer
    server.open("vpp-service-test-server", "rec-s")
    server.attach()
    try:
        time.sleep(PROBE_INTERVAL_S)
        assert out.send(parts(2)) and out.send(parts(3))
        assert counts == Counter({"reconnects": 1})
        out.flush_and_disconnect(time.monotonic() + 5)
    finally:
        server.stop_server()


def test_serve_starts_a_server_and_stop_server_ends_it():
    port = free_port()
    out, counts = output(mode="serve", grpc_port=port)
    out.open("vpp-service-test", "rec-1")
    out.attach()
    try:
        url = f"rerun+http://127.0.0.1:{port}/proxy"
        assert out.server_uri == url and reachable(url)
        assert out.send(parts(0)) and counts == Counter()
        out.flush_and_disconnect(time.monotonic() + 5)
    finally:
        out.stop_server()
    assert not reachable(url, 0.2)
    out.stop_server()  # a second stop is a no-op
