"""Tests of the ``rerun`` sink (real .rrd files read back with rerun.chunk) and the colouriser."""

from __future__ import annotations

import logging
import math
import socket
import subprocess
import time

import cv2
import numpy as np
import psutil
import pytest
import rerun as rr
from rerun.chunk import RrdReader

from helpers.rerun_rrd import read_rrd
from vpp_service.frame import Calibration, FusionResult, StereoFrame
from vpp_service.settings import SettingsError
from vpp_service.sinks import SINKS, build_sink
from vpp_service.sinks.base import SinkContext
from vpp_service.sinks.colorize import colorize_disparity, disparity_range
from vpp_service.sinks.rerun import RerunSink, depth_stride, rotated_paths
from vpp_service.sinks.rerun_log import robust_range
from vpp_service.sinks.rerun_output import _rerun_binary, reachable

H, W = 30, 40
RIG = "rigA"


def make_result(seq: int, *, painted: bool = True, calib: bool = True) -> FusionResult:
    rng = np.random.default_rng(seq)
    left = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
    right = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
    sparse = np.full((H, W), np.nan, np.float32)
    sparse[2, 3], sparse[20, 30], sparse[7, 11] = 12.0, 25.0, 5.0
    disp = rng.uniform(2.0, 30.0, (H, W)).astype(np.float32)
    disp[0, :4] = np.nan
    frame = StereoFrame(
        left,
        right,
        Calibration(f=80.0, baseline=0.2, cx=19.0, cy=14.0) if calib else None,
        sparse_disparity=sparse,
        rig=RIG,
        seq=seq,
        stamp_ns=1_700_000_000_000_000_000 + seq * 10**8,
    )
    return FusionResult(
        frame,
        disp,
        left_vpp=(255 - left) if painted else None,
        right_vpp=(255 - right) if painted else None,
        timing_ms={"vpp": 1.5, "total": 9.0},
    )


def save_sink(tmp_path, **opts) -> RerunSink:
    opts = {"mode": "save", "path": str(tmp_path / "out.rrd"), "max_hz": 0, "queue_size": 64, **opts}
    sink = build_sink("rerun", opts, SinkContext(rig=RIG))
    sink.open()
    return sink


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def image_bytes(value) -> np.ndarray:
    return np.asarray(value[0] if isinstance(value[0], list) else value, dtype=np.uint8)


# -- rerun sink: save mode ----------------------------------------------------------


def test_registered():
    assert SINKS.get("rerun") is RerunSink


def test_save_contains_expected_entities(tmp_path):
    sink = save_sink(tmp_path, jpeg_quality=0)
    results = [make_result(i) for i in range(4)]
    for r in results:
        sink.write(r)
    sink.close(timeout=10)
    assert sink.stats()["written"] == 4 and sink.stats()["dropped"] == 0 and sink.stats()["errors"] == 0

    reader = RrdReader(tmp_path / "out.rrd")
    assert len(reader.recordings()) == 1 and len(reader.blueprints()) == 1
    assert reader.recordings()[0].application_id == f"vpp-service-{RIG}"
    assert reader.recordings()[0].recording_id.startswith(f"{RIG}-")
    data = read_rrd(tmp_path / "out.rrd")
    expected = {
        f"/{RIG}/{e}"
        for e in ("left", "right", "left/sparse", "disparity", "camera", "camera/depth", "timing/vpp", "timing/total")
    }
    assert set(data) == expected
    for ent in expected:
        assert data[ent]["seq"] == [0, 1, 2, 3], ent
        assert data[ent]["stamp"] == [r.frame.stamp_ns for r in results], ent
    # painted pair logged (not the raw one)
    assert np.array_equal(image_bytes(data[f"/{RIG}/left"]["Image:buffer"][2]), results[2].left_vpp.ravel())
    assert np.array_equal(image_bytes(data[f"/{RIG}/right"]["Image:buffer"][0]), results[0].right_vpp.ravel())
    # sparse points at pixel centres (Rerun: +0.5), in raster order, small (negative radius = UI points)
    pos = np.asarray(data[f"/{RIG}/left/sparse"]["Points2D:positions"][0])
    assert np.allclose(pos, [[3.5, 2.5], [11.5, 7.5], [30.5, 20.5]])
    assert np.allclose(data[f"/{RIG}/left/sparse"]["Points2D:radii"][0], [-1.0])
    # pinhole from the calibration (column-major 3x3)
    k = np.asarray(data[f"/{RIG}/camera"]["Pinhole:image_from_camera"][0]).reshape(3, 3).T
    assert np.allclose(k, [[80.0, 0, 19.5], [0, 80.0, 14.5], [0, 0, 1]])
    assert np.allclose(data[f"/{RIG}/timing/total"]["Scalars:scalars"][1], [9.0])
    # disparity is data (a depth image in pixels, invalid = 0) with a colour map over one fixed range
    disp = data[f"/{RIG}/disparity"]
    values = np.frombuffer(bytes(image_bytes(disp["DepthImage:buffer"][1])), np.float32).reshape(H, W)
    assert np.array_equal(values, np.nan_to_num(results[1].disparity, nan=0.0))
    first = robust_range(results[0].disparity)
    for i in range(4):
        assert np.allclose(disp["DepthImage:depth_range"][i], [first]), i
        assert disp["DepthImage:colormap"][i] == [rr.components.Colormap.Turbo.value]


def test_pair_is_jpeg_by_default(tmp_path):
    res = make_result(0)
    raw = save_sink(tmp_path, jpeg_quality=0, path=str(tmp_path / "raw.rrd"))
    jpg = save_sink(tmp_path, path=str(tmp_path / "jpg.rrd"))
    for sink in (raw, jpg):
        sink.write(res)
        sink.close(timeout=10)
    data = read_rrd(tmp_path / "jpg.rrd")
    left = data[f"/{RIG}/left"]
    assert "Image:buffer" not in left and left["EncodedImage:media_type"][0] == ["image/jpeg"]
    img = cv2.imdecode(image_bytes(left["EncodedImage:blob"][0]), cv2.IMREAD_COLOR)[..., ::-1]
    assert img.shape == res.left_vpp.shape
    # JPEG keeps the picture: a 3x3 box blur of the random image survives within a few grey levels
    blur = cv2.blur(img, (3, 3)).astype(float) - cv2.blur(res.left_vpp, (3, 3)).astype(float)
    assert np.abs(blur).mean() < 40
    big = np.random.default_rng(0).integers(0, 256, (240, 320), dtype=np.uint8)
    smooth = cv2.GaussianBlur(big, (0, 0), 3)
    assert len(cv2.imencode(".jpg", smooth)[1]) < smooth.size / 4  # the reason for compressing


def test_fixed_ranges_and_sparse_options(tmp_path):
    sink = save_sink(tmp_path, disparity_range=[1.0, 50.0], depth_range=[0.5, 4.0], max_sparse_points=2, jpeg_quality=0)
    sink.write(make_result(0))
    sink.close(timeout=10)
    data = read_rrd(tmp_path / "out.rrd")
    assert np.allclose(data[f"/{RIG}/disparity"]["DepthImage:depth_range"][0], [[1.0, 50.0]])
    assert np.allclose(data[f"/{RIG}/camera/depth"]["DepthImage:depth_range"][0], [[0.5, 4.0]])
    # farther than the depth range: left out of the 3-D cloud
    depth = np.frombuffer(bytes(image_bytes(data[f"/{RIG}/camera/depth"]["DepthImage:buffer"][0])), np.float32)
    assert depth.max() <= 4.0 and (depth == 0).sum() > 4
    assert len(data[f"/{RIG}/left/sparse"]["Points2D:positions"][0]) == 2

    sink = save_sink(tmp_path, sparse_points=False, path=str(tmp_path / "nosparse.rrd"))
    sink.write(make_result(0))
    sink.close(timeout=10)
    assert f"/{RIG}/left/sparse" not in read_rrd(tmp_path / "nosparse.rrd")


def test_blueprint_opens_3d_view_on_the_scene(tmp_path):
    sink = build_sink("rerun", {"depth_range": [2.0, 6.0]}, SinkContext(rig=RIG))
    view = sink.blueprint().root_container.contents[1].contents[1]
    assert str(view.origin) == f"/{RIG}"
    eye = view.properties["EyeControls3D"]  # looks at the middle of the depth range from behind the camera
    assert np.allclose(eye.look_target.as_arrow_array().to_pylist()[0], [0, 0, 4.0])
    assert eye.position.as_arrow_array().to_pylist()[0][2] < 0


def test_rigs_have_their_own_recordings(tmp_path):
    for rig in ("rig0", "rig1"):
        sink = build_sink("rerun", {"path": str(tmp_path / f"{rig}.rrd"), "max_hz": 0}, SinkContext(rig=rig))
        sink.open()
        sink.write(make_result(0))
        sink.close(timeout=10)
    ids = [RrdReader(tmp_path / f"{rig}.rrd").recordings()[0] for rig in ("rig0", "rig1")]
    assert [i.application_id for i in ids] == ["vpp-service-rig0", "vpp-service-rig1"]
    assert ids[0].recording_id.startswith("rig0-") and ids[1].recording_id.startswith("rig1-")


def test_save_rotates_at_the_cap(tmp_path):
    path = tmp_path / "vpp.rrd"
    sink = save_sink(tmp_path, path=str(path), jpeg_quality=0, max_mb=0.5, max_files=3)
    n = 60
    for i in range(n):
        sink.write(make_result(i))
        time.sleep(0.01)
    sink.close(timeout=20)
    st = sink.stats()
    assert st["written"] == n and st["errors"] == 0 and 3 <= st["rotations"] < n / 3
    files = rotated_paths(path, 3)
    assert all(f.exists() for f in files)
    assert not (tmp_path / "vpp.3.rrd").exists() and len(list(tmp_path.iterdir())) == 3
    seqs = []
    for f in files:  # newest first; each part is a complete recording
        reader = RrdReader(f)
        assert len(reader.recordings()) == 1 and len(reader.blueprints()) == 1
        seqs.append(read_rrd(f)[f"/{RIG}/left"]["seq"])
        assert f.stat().st_size < 0.5e6 + 150_000  # the cap plus about one frame
    assert seqs[0][-1] == n - 1 and all(len(q) > 1 for q in seqs)
    assert seqs[2][-1] < seqs[1][0] and seqs[1][-1] < seqs[0][0]


def test_depth_image_matches_disparity(tmp_path):
    sink = save_sink(tmp_path, max_points=400, depth_range=[0.1, 100.0])  # 30x40 -> stride 2 -> 15x20 points
    res = make_result(0)
    sink.write(res)
    sink.close(timeout=10)
    data = read_rrd(tmp_path / "out.rrd")
    res_wh = data[f"/{RIG}/camera"]["Pinhole:resolution"][0]
    assert list(res_wh[0]) == [20, 15]
    k = np.asarray(data[f"/{RIG}/camera"]["Pinhole:image_from_camera"][0]).reshape(3, 3).T
    assert np.allclose(k, [[40.0, 0, 10.0], [0, 40.0, 7.5], [0, 0, 1]])
    depth = np.frombuffer(bytes(image_bytes(data[f"/{RIG}/camera/depth"]["DepthImage:buffer"][0])), np.float32)
    depth = depth.reshape(15, 20)
    ref = (80.0 * 0.2 / res.disparity[::2, ::2]).astype(np.float32)
    ref[~np.isfinite(ref)] = 0.0
    assert np.allclose(depth, ref, rtol=1e-6)


@pytest.mark.parametrize(
    ("opts", "painted", "calib", "raw", "has_camera"),
    [
        ({"log_painted": False}, True, True, True, True),
        ({}, False, True, True, True),  # VPP disabled -> raw pair
        ({"point_cloud": False}, True, True, False, False),
        ({}, True, False, False, False),  # no calibration -> no 3-D
    ],
)
def test_save_variants(tmp_path, opts, painted, calib, raw, has_camera):
    sink = save_sink(tmp_path, jpeg_quality=0, **opts)
    res = make_result(5, painted=painted, calib=calib)
    sink.write(res)
    sink.close(timeout=10)
    data = read_rrd(tmp_path / "out.rrd")
    left = image_bytes(data[f"/{RIG}/left"]["Image:buffer"][0])  # jpeg_quality = 0: exact
    expected = res.frame.left if raw else res.left_vpp
    assert np.array_equal(left, expected.ravel())
    assert (f"/{RIG}/camera/depth" in data) == has_camera


def test_throttled_frames_are_counted_apart_from_losses(tmp_path):
    sink = save_sink(tmp_path, max_hz=0.001)  # one frame per 1000 s: only the bucket's two frames pass
    for i in range(5):
        sink.write(make_result(i))
    sink.close(timeout=10)
    st = sink.stats()
    assert st["written"] == 2 and st["throttled"] == 3 and st["dropped"] == 0
    assert read_rrd(tmp_path / "out.rrd")[f"/{RIG}/left"]["seq"] == [0, 1]


@pytest.mark.parametrize(("mode", "expected"), [("save", 0.0), ("connect", 15.0), ("serve", 15.0)])
def test_default_throttle_logs_every_saved_frame_and_caps_viewers(mode, expected):
    sink = build_sink("rerun", {"mode": mode}, SinkContext(rig=RIG))
    assert sink.max_hz == expected


def test_a_10hz_camera_with_jitter_is_not_throttled(tmp_path):
    sink = save_sink(tmp_path, max_hz=10.0)
    rng = np.random.default_rng(0)
    for i in range(12):  # 10 Hz on average, each interval 100 ms +- 20 ms
        sink.write(make_result(i))
        time.sleep(0.1 + rng.uniform(-0.02, 0.02))
    sink.close(timeout=10)
    assert sink.stats()["throttled"] == 0 and sink.stats()["written"] == 12


def test_every_write_is_logged_synchronously(tmp_path):
    """write() logs on the caller's thread (the pipeline gives the sink its own thread and queue)."""
    sink = save_sink(tmp_path, queue_size=1)
    results = [make_result(i) for i in range(3)]
    n = 12
    for i in range(n):
        results[i % 3].frame.seq = i
        sink.write(results[i % 3])
        assert sink.stats()["written"] == i + 1
    sink.close(timeout=20)
    st = sink.stats()
    assert st["written"] == n and st["dropped"] == 0
    assert read_rrd(tmp_path / "out.rrd")[f"/{RIG}/left"]["seq"] == list(range(n))


def test_connect_to_dead_viewer_closes_within_bound():
    url = f"rerun+http://127.0.0.1:{free_port()}/proxy"
    sink = build_sink("rerun", {"mode": "connect", "url": url, "max_hz": 0}, SinkContext(rig=RIG))
    t0 = time.monotonic()
    sink.open()
    assert time.monotonic() - t0 < 3.0  # the connection is made on the sink's thread
    for i in range(3):
        sink.write(make_result(i))
    t1 = time.monotonic()
    sink.close(timeout=1.0)
    assert time.monotonic() - t1 < 4.0  # Rerun itself would wait 5 s + 5 s
    with pytest.raises(RuntimeError, match="after close"):
        sink.write(make_result(0))


def test_throttled_frames_are_said(tmp_path, caplog):
    sink = save_sink(tmp_path, max_hz=0.001)
    with caplog.at_level(logging.INFO, logger="vpp_service.sinks.rerun"):
        for i in range(4):
            sink.write(make_result(i))
    sink.close(timeout=10)
    said = [r.getMessage() for r in caplog.records if "(max_hz)" in r.getMessage()]
    assert len(said) == 1 and "throttled" in said[0] and sink.stats()["throttled"] == 2


def start_viewer(port: int, path) -> subprocess.Popen:
    """A stand-in viewer: Rerun's own gRPC server, saving what it receives to ``path``."""
    proc = subprocess.Popen(
        [*_rerun_binary(), "--serve-grpc", "--bind", "127.0.0.1", "--port", str(port), "--save", str(path)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    deadline = time.monotonic() + 10
    while not reachable(f"rerun+http://127.0.0.1:{port}/proxy", 0.2):
        assert time.monotonic() < deadline and proc.poll() is None, "viewer did not start"
        time.sleep(0.05)
    return proc


def stop(proc: subprocess.Popen) -> None:
    proc.terminate()
    proc.wait(timeout=10)


def connected_sink(tmp_path) -> tuple[int, subprocess.Popen, RerunSink]:
    """A stand-in viewer saving to ``a.rrd`` and a ``connect`` sink that has delivered frames 0-4 to it."""
    port = free_port()
    url = f"rerun+http://127.0.0.1:{port}/proxy"
    viewer = start_viewer(port, tmp_path / "a.rrd")
    sink = build_sink("rerun", {"mode": "connect", "url": url, "max_hz": 0, "queue_size": 64}, SinkContext(rig=RIG))
    sink.open()
    try:
        for seq in range(5):
            sink.write(make_result(seq))
            time.sleep(0.05)
        deadline = time.monotonic() + 10
        while sink.stats()["written"] < 5 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert sink.stats()["written"] == 5
    except BaseException:
        stop(viewer)
        raise
    assert isinstance(sink, RerunSink)
    return port, viewer, sink


def test_connect_reconnects_after_viewer_restart(tmp_path):
    port, viewer, sink = connected_sink(tmp_path)
    seq = 5
    try:
        stop(viewer)
        for _ in range(5):  # nobody listens: counted, not buffered
            sink.write(make_result(seq))
            seq += 1
            time.sleep(0.1)
        viewer = start_viewer(port, tmp_path / "b.rrd")
        back = time.monotonic()
        while sink.stats()["reconnects"] == 0 and time.monotonic() - back < 10:
            sink.write(make_result(seq))
            seq += 1
            time.sleep(0.1)
        reconnect_s = time.monotonic() - back
        assert sink.stats()["reconnects"] == 1 and reconnect_s < 5.0
        for _ in range(3):
            sink.write(make_result(seq))
            seq += 1
            time.sleep(0.1)
        sink.close(timeout=10)
    finally:
        stop(viewer)
    st = sink.stats()
    assert st["undelivered"] >= 5 and st["written"] + st["undelivered"] == seq
    assert st["dropped"] == st["undelivered"]
    after = read_rrd(tmp_path / "b.rrd")[f"/{RIG}/left"]["seq"]
    assert after[-1] == seq - 1 and len(after) >= 3 and min(after) >= 10
    assert read_rrd(tmp_path / "a.rrd")[f"/{RIG}/left"]["seq"] == [0, 1, 2, 3, 4]


def test_connect_without_viewer_counts_and_buffers_nothing():
    url = f"rerun+http://127.0.0.1:{free_port()}/proxy"
    sink = build_sink("rerun", {"mode": "connect", "url": url, "max_hz": 0, "queue_size": 4}, SinkContext(rig=RIG))
    sink.open()
    n = 40
    for i in range(n):
        sink.write(make_result(i))
        time.sleep(0.005)
    sink.close(timeout=5)
    st = sink.stats()
    assert st["written"] == 0 and st["undelivered"] == n


@pytest.mark.parametrize("bind", ["127.0.0.1", "127.0.0.2"])  # configurable; tests stay on loopback
def test_serve_binds_loopback_by_default(bind):
    port, web = free_port(), free_port()
    opts = {"mode": "serve", "grpc_port": port, "web_port": web, "memory_limit": "64MB"}
    if bind != "127.0.0.1":
        opts["bind"] = bind
    sink = build_sink("rerun", opts, SinkContext(rig=RIG))
    sink.open()
    try:
        assert sink.wait_ready(15) and sink.stats()["errors"] == 0

        def listening() -> set[tuple[str, int]]:
            return {
                (c.laddr.ip, c.laddr.port)
                for c in psutil.net_connections(kind="tcp")
                if c.status == psutil.CONN_LISTEN and c.laddr.port in (port, web)
            }

        deadline = time.monotonic() + 10  # the web viewer's port may open a moment after the gRPC one
        while len(listening()) < 2 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert listening() == {(bind, port), (bind, web)}
        sink.write(make_result(0))
    finally:
        sink.close(timeout=5)
    assert sink.stats()["errors"] == 0


def test_serve_listens_on_grpc_port():
    port = free_port()
    sink = build_sink("rerun", {"mode": "serve", "grpc_port": port, "memory_limit": "64MB"}, SinkContext(rig=RIG))
    sink.open()
    assert sink.wait_ready(10)
    assert sink.server_uri and str(port) in sink.server_uri
    sink.write(make_result(0))
    deadline = time.monotonic() + 10
    while True:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
            break
        except OSError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.1)
    sink.close(timeout=5)
    assert sink.stats()["errors"] == 0


def test_save_missing_folder(tmp_path):
    sink = build_sink("rerun", {"path": str(tmp_path / "no" / "x.rrd")})
    with pytest.raises(FileNotFoundError, match=r"sinks\.rerun\.path"):
        sink.open()


def test_write_errors(tmp_path):
    sink = build_sink("rerun", {"path": str(tmp_path / "x.rrd")})
    with pytest.raises(RuntimeError, match="before open"):
        sink.write(make_result(0))
    sink.open()
    with pytest.raises(TypeError, match="result"):
        sink.write({"disparity": 1})
    sink.close()


def test_bad_rig_name():
    with pytest.raises(ValueError, match=r"context\.rig"):
        build_sink("rerun", {}, SinkContext(rig="a/b c"))


@pytest.mark.parametrize(
    ("opts", "key"),
    [
        ({"mode": "tcp"}, "mode"),
        ({"max_hz": -1}, "max_hz"),
        ({"max_hz": "fast"}, "max_hz"),
        ({"memory_limit": "lots"}, "memory_limit"),
        ({"queue_size": 0}, "queue_size"),
        ({"url": "http://127.0.0.1:9876"}, "url"),
        ({"grpc_port": 0}, "grpc_port"),
        ({"web_port": 70000}, "web_port"),
        ({"max_points": 0}, "max_points"),
        ({"path": ""}, "path"),
        ({"log_painted": 1}, "log_painted"),
        ({"viewer": "x"}, "viewer"),
    ],
)
def test_bad_options(opts, key):
    with pytest.raises(SettingsError, match=rf"sinks\.rerun.*{key}"):
        build_sink("rerun", opts)


# -- depth_stride ---------------------------------------------------------------------


@pytest.mark.parametrize(("h", "w", "m"), [(30, 40, 400), (30, 40, 1200), (30, 40, 1), (480, 640, 200_000), (7, 3, 5)])
def test_depth_stride_reference(h, w, m):
    ref = next(s for s in range(1, h * w + 1) if math.ceil(h / s) * math.ceil(w / s) <= m)
    assert depth_stride(h, w, m) == ref


@pytest.mark.parametrize(
    ("args", "bad"),
    [
        ((0, 4, 4), "height"),
        ((4, -1, 4), "width"),
        ((4, 4, 0), "max_points"),
        ((4.0, 4, 4), "height"),
        ((True, 4, 4), "height"),
    ],
)
def test_depth_stride_errors(args, bad):
    with pytest.raises(ValueError, match=f"^{bad}: must be an integer >= 1"):
        depth_stride(*args)


# -- colorize ---------------------------------------------------------------------------


def test_colorize_reference():
    d = np.array([[np.nan, 0.0, 1.0], [5.0, 9.0, 20.0]], np.float32)
    out = colorize_disparity(d, 1.0, 9.0)
    assert out.shape == (2, 3, 3) and out.dtype == np.uint8
    idx = np.clip(np.rint((np.nan_to_num(d) - 1.0) * 255.0 / 8.0), 0, 255).astype(np.uint8)
    ref = cv2.applyColorMap(idx, cv2.COLORMAP_TURBO)[..., ::-1]
    valid = np.isfinite(d) & (d > 0)
    assert np.array_equal(out[valid], ref[valid])
    assert np.all(out[~valid] == 0)


def test_colorize_default_range_and_points():
    d = np.array([2.0, 4.0, np.inf, 3.0], np.float32)
    assert disparity_range(d) == (2.0, 4.0)
    out = colorize_disparity(d)
    assert out.shape == (4, 3)
    assert np.array_equal(out[0], colorize_disparity(np.array([2.0]), 2.0, 4.0)[0])
    assert np.all(out[2] == 0)


def test_disparity_range():
    assert disparity_range(None, np.array([np.nan, -1.0])) is None
    assert disparity_range(np.array([3.0, 3.0])) == (3.0, 4.0)
    assert disparity_range(np.array([1.0, 5.0]), None, np.array([0.5, np.nan])) == (0.5, 5.0)
    with pytest.raises(TypeError, match=r"arrays\[0\]"):
        disparity_range([1.0, 2.0])


@pytest.mark.parametrize(
    ("args", "exc", "key"),
    [
        (("x",), TypeError, "disparity"),
        ((np.zeros(3, bool),), TypeError, "disparity"),
        ((np.ones(3), 2.0, 1.0), ValueError, "vmax"),
        ((np.ones(3), np.nan, 1.0), ValueError, "vmin"),
    ],
)
def test_colorize_errors(args, exc, key):
    with pytest.raises(exc, match=key):
        colorize_disparity(*args)


def test_accuracy_against_ground_truth_is_logged_as_scalars(tmp_path):
    from vpp_service.fusion import score

    sink = save_sink(tmp_path)
    results = [make_result(i) for i in range(2)]
    for r in results:
        r.frame.gt_disparity = np.where(np.isfinite(r.disparity), r.disparity, 10.0) + np.float32(r.frame.seq * 3)
        r.metrics = score(r.disparity, r.frame)  # what the service's fusion step reports
        sink.write(r)
    sink.close(timeout=10)
    data = read_rrd(tmp_path / "out.rrd")
    for name in ("bad2_answered", "density", "bad2_filled"):
        logged = [v[0] for v in data[f"/{RIG}/accuracy/{name}"]["Scalars:scalars"]]
        assert np.allclose(logged, [r.metrics[name] for r in results]), name


def test_no_accuracy_entity_without_ground_truth(tmp_path):
    sink = save_sink(tmp_path)
    sink.write(make_result(0))
    sink.close(timeout=10)
    assert not [e for e in read_rrd(tmp_path / "out.rrd") if "/accuracy" in e]


def test_frames_after_the_viewer_dies_are_not_counted_written(tmp_path):
    """The viewer (a gRPC server saving what it gets) stops mid-stream: each frame counted ``written`` reached it."""
    _, viewer, sink = connected_sink(tmp_path)
    n = 15
    try:
        viewer.kill()  # dies: no goodbye on the connection
        viewer.wait(10)
        for seq in range(5, n):
            sink.write(make_result(seq))
            time.sleep(0.05)
        sink.close(timeout=5)
    finally:
        if viewer.poll() is None:
            stop(viewer)
    st = sink.stats()
    assert st["written"] == 5 and st["undelivered"] == n - 5, st


# -- points: rr.Points3D beside the pinhole ------------------------------------------------


def _rgba_to_rgb(colors) -> np.ndarray:
    c = np.asarray(colors, dtype=np.uint64)
    return np.stack([(c >> 24) & 255, (c >> 16) & 255, (c >> 8) & 255], axis=1).astype(np.uint8)


@pytest.mark.parametrize("stride", [1, 3])
def test_points3d_are_the_depth_map_and_line_up_with_the_pinhole(tmp_path, stride):
    """``<rig>/points`` is the clipped depth map's coloured cloud, and it lines up with the camera.

    Projected by the logged pinhole, each point lands on the logged depth image's pixel of the same depth.
    """
    from helpers.points import assert_cloud_is_depth, clipped_result

    sink = save_sink(tmp_path, jpeg_quality=0, points=True, points_stride=stride, depth_range=[0.1, 100.0])
    res = clipped_result(seq=4, rig=RIG)
    res.depth = None  # the sink back-projects the clipped disparity itself, as it does for the depth image
    sink.write(res)
    sink.close(timeout=10)
    data = read_rrd(tmp_path / "out.rrd")
    pts = data[f"/{RIG}/points"]
    xyz = np.asarray(pts["Points3D:positions"][0], np.float32)
    rgb = _rgba_to_rgb(pts["Points3D:colors"][0])
    ref = clipped_result(seq=4, rig=RIG)  # the same (deterministic) frame, with the fusion step's depth
    assert_cloud_is_depth(xyz, rgb, ref, stride)
    k = np.asarray(data[f"/{RIG}/camera"]["Pinhole:image_from_camera"][0]).reshape(3, 3).T
    depth = np.frombuffer(bytes(image_bytes(data[f"/{RIG}/camera/depth"]["DepthImage:buffer"][0])), np.float32)
    depth = depth.reshape(ref.depth.shape)  # 64 x 128 is within max_points: not decimated
    uvw = (k @ xyz.T.astype(np.float64)).T
    u = np.rint(uvw[:, 0] / uvw[:, 2] - 0.5).astype(int)  # Rerun's pixel centres are at +0.5
    v = np.rint(uvw[:, 1] / uvw[:, 2] - 0.5).astype(int)
    np.testing.assert_allclose(depth[v, u], xyz[:, 2], rtol=1e-6)


def test_points_without_the_depth_image_keep_the_pinhole(tmp_path):
    from helpers.points import clipped_result

    sink = save_sink(tmp_path, points=True, point_cloud=False)
    sink.write(clipped_result(rig=RIG))
    sink.close(timeout=10)
    data = read_rrd(tmp_path / "out.rrd")
    assert f"/{RIG}/points" in data and f"/{RIG}/camera" in data and f"/{RIG}/camera/depth" not in data


@pytest.mark.parametrize("bad", [0, 100, "4"])
def test_bad_points_stride_is_refused(bad):
    with pytest.raises(SettingsError, match=r"sinks\.rerun.*points_stride"):
        build_sink("rerun", {"points": True, "points_stride": bad}, SinkContext(rig=RIG))


def test_confidence_image(tmp_path):
    """``confidence = true``: the map as a DepthImage on <rig>/confidence (values as given), the blueprint shows it."""
    sink = save_sink(tmp_path, confidence=True)
    assert RerunSink.needs_confidence(sink.options) and sink.layout.confidence
    assert not RerunSink.needs_confidence(build_sink("rerun", {"mode": "save"}, SinkContext(rig=RIG)).options)
    res = make_result(0)
    res.confidence = np.random.default_rng(2).random((H, W), dtype=np.float32)
    sink.write(res)
    sink.write(make_result(1))  # no confidence computed for it: nothing logged
    sink.close(timeout=10)
    data = read_rrd(tmp_path / "out.rrd")
    logged = data[f"/{RIG}/confidence"]["DepthImage:buffer"]
    assert len(logged) == 1
    conf = np.frombuffer(bytes(image_bytes(logged[0])), np.float32).reshape(H, W)
    np.testing.assert_array_equal(conf, res.confidence)
