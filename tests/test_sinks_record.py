"""Tests of the ``record`` sink: real recordings in tmp_path, replayed by the real ``files`` source."""

from __future__ import annotations

import logging
import re
import signal
import stat
import threading

import numpy as np
import pytest

from vpp_service.frame import Calibration, FusionResult, StereoFrame
from vpp_service.settings import SettingsError
from vpp_service.sinks import SINKS, build_sink
from vpp_service.sinks.base import SinkContext
from vpp_service.sinks.folder import write_atomic
from vpp_service.sinks.record import RecordSink
from vpp_service.sources.base import SourceContext, build_source
from vpp_service.sources.sim import motorcycle_frame
from vpp_service.transport import wire
from vpp_service.vpp import depth_to_disparity

H, W = 32, 64


# ------------------------------------------------------------------ helpers
def sim_frames(n: int, sensor: str = "uniform") -> list[StereoFrame]:
    """``n`` frames of the real simulator (synthetic scene, sparse disparity, ground truth)."""
    src = build_source(
        "sim",
        {
            "scene": "synthetic",
            "sensor": sensor,
            "scene_options": {"height": H, "width": W, "max_disparity": 8},
            "rate_hz": 0,
            "count": n,
        },
        SourceContext(rig="rigA"),
    )
    src.open()
    return [src.frame(i) for i in range(n)]


def metric_frame(seq: int = 0) -> StereoFrame:
    """A hand-built grayscale frame with metric sensor depth and ground truth with holes."""
    rng = np.random.default_rng(seq)
    left = rng.integers(0, 256, (H, W), dtype=np.uint8)
    right = rng.integers(0, 256, (H, W), dtype=np.uint8)
    depth = np.full((H, W), np.nan, np.float32)
    ys, xs = rng.integers(0, H, 40), rng.integers(0, W, 40)
    depth[ys, xs] = rng.uniform(0.5, 20.0, 40).astype(np.float32)
    gt = rng.uniform(1.0, 30.0, (H, W)).astype(np.float32)
    gt[5, :10] = np.nan
    calib = Calibration(f=412.5, baseline=0.12, doffs=1.5, cx=31.0, cy=15.5)
    return StereoFrame(
        left, right, calib, sensor_depth=depth, gt_disparity=gt, rig="cam", seq=seq, stamp_ns=1_000 + seq
    )


def as_result(frame: StereoFrame) -> FusionResult:
    return FusionResult(frame, np.zeros(frame.shape, np.float32))


def make_sink(tmp_path, **opts) -> RecordSink:
    opts.setdefault("dir", str(tmp_path))
    sink = build_sink("record", opts, SinkContext(rig="ctxrig"))
    sink.open()
    return sink


def replay(folder, **opts) -> tuple[list[StereoFrame], list[str]]:
    """Play ``folder`` with the real files source; returns (frames, rejects)."""
    opts = {"root": str(folder), "format": "msgpack", "sensor": "none", **opts}
    src = build_source("files", opts, SourceContext(rig="replay"))
    frames, rejects = [], []
    src.open()
    src.start(lambda f: frames.append(f) or True, rejects.append)
    assert src.finished.wait(20.0)
    src.stop(1.0)
    return frames, rejects


def assert_same_optional(a, b) -> None:
    assert (a is None) == (b is None)
    if a is not None:
        assert a.dtype == b.dtype == np.float32
        np.testing.assert_array_equal(a, b)  # NaN == NaN here: byte-equal maps


def assert_same_frame(got: StereoFrame, ref: StereoFrame) -> None:
    assert got.left.dtype == np.uint8 and got.left.shape == ref.left.shape
    np.testing.assert_array_equal(got.left, ref.left)
    np.testing.assert_array_equal(got.right, ref.right)
    assert got.calib == ref.calib
    # the sparse depth the fusion consumes: sparse disparity when present, else metric depth
    # (which replays with its disparity, computed at the points)
    if ref.sparse_disparity is None and ref.sensor_depth is not None:
        c = got.calib
        assert_same_optional(got.sparse_disparity, depth_to_disparity(ref.sensor_depth, c.f, c.baseline, c.doffs))
    else:
        assert_same_optional(got.sparse_disparity, ref.sparse_disparity)
    assert_same_optional(got.sensor_depth, None if ref.sparse_disparity is not None else ref.sensor_depth)
    assert_same_optional(got.gt_disparity, ref.gt_disparity)


# --------------------------------------------------------------------- tests
def test_registered():
    assert SINKS.get("record") is RecordSink
    assert "record" in SINKS.names()


@pytest.mark.parametrize("enc", ["png", "raw"])
def test_sim_frames_round_trip_through_files_source(tmp_path, enc):
    ref = sim_frames(3)
    assert all(f.sparse_disparity is not None and f.gt_disparity is not None for f in ref)
    with make_sink(tmp_path, enc=enc) as sink:
        for f in ref:
            sink.write(as_result(f))
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"rigA_{i:09d}.msgpack" for i in range(3)]
    st = sink.stats()
    assert (st["written"], st["errors"], st["skipped"], st["dropped"]) == (3, 0, 0, 0)
    assert st["bytes"] == sum(p.stat().st_size for p in tmp_path.iterdir())
    frames, rejects = replay(tmp_path)
    assert not rejects and [f.seq for f in frames] == [0, 1, 2]
    for got, r in zip(frames, ref, strict=True):
        assert_same_frame(got, r)
    # the stored message is exactly the wire encoding of the input frame
    assert (tmp_path / "rigA_000000001.msgpack").read_bytes() == wire.encode_frame(ref[1], enc, "disparity_points")


def test_metric_depth_grayscale_round_trip(tmp_path):
    ref = [metric_frame(s) for s in (0, 1)]
    with make_sink(tmp_path) as sink:
        for f in ref:
            sink.write(as_result(f))
    frames, rejects = replay(tmp_path)
    assert not rejects and len(frames) == 2
    for got, r in zip(frames, ref, strict=True):
        assert got.left.ndim == 2 and got.sparse_disparity is not None
        assert_same_frame(got, r)


def test_replay_order_is_seq_order(tmp_path):
    seqs = [100, 7, 2_000_000, 8]
    with make_sink(tmp_path) as sink:
        for s in seqs:
            sink.write(as_result(metric_frame(s)))
    frames, _ = replay(tmp_path)
    order = sorted(seqs)
    for got, s in zip(frames, order, strict=True):
        np.testing.assert_array_equal(got.left, metric_frame(s).left)


def test_publish_path_auto_detects_a_recording(tmp_path):
    """``vpp-service publish --dataset auto --root DIR`` builds a files source with format "dataset"."""
    ref = sim_frames(2)
    with make_sink(tmp_path) as sink:
        for f in ref:
            sink.write(as_result(f))
    frames, rejects = replay(tmp_path, format="dataset", dataset="auto", sensor="uniform")
    assert not rejects and len(frames) == 2
    for got, r in zip(frames, ref, strict=True):
        assert_same_frame(got, r)  # recorded sparse depth kept, not re-simulated
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(ValueError, match="dataset layout"):
        build_source("files", {"root": str(empty)}).open()


def test_frames_without_depth_or_gt(tmp_path):
    ref = sim_frames(1, sensor="none")[0].with_(gt_disparity=None)
    with make_sink(tmp_path) as sink:
        sink.write(as_result(ref))
    (got,), _ = replay(tmp_path)
    assert got.sparse_disparity is None and got.sensor_depth is None and got.gt_disparity is None
    assert_same_frame(got, ref)


def test_png_is_smaller_than_raw_on_a_natural_image(tmp_path):
    frame = motorcycle_frame(scale=0.25).with_(gt_disparity=None)  # float32 ground truth is stored raw
    sizes = {}
    for enc in ("png", "raw"):
        d = tmp_path / enc
        with make_sink(d, create_dir=True, enc=enc) as sink:
            sink.write(as_result(frame))
        sizes[enc] = sink.stats()["bytes"]
    assert sizes["png"] < 0.85 * sizes["raw"], sizes  # measured: 0.71
    (got,), _ = replay(tmp_path / "png")
    assert_same_frame(got, frame)


def test_max_frames_stops_and_logs_once(tmp_path, caplog):
    frame = metric_frame()
    with (
        caplog.at_level(logging.WARNING, logger="vpp_service.sinks.record"),
        make_sink(tmp_path, max_frames=2) as sink,
    ):
        for s in range(5):
            assert sink.stopped is (None if s < 2 else "max_frames")
            sink.write(as_result(frame.with_(seq=s)))
    assert len(list(tmp_path.glob("*.msgpack"))) == 2
    st = sink.stats()
    assert (st["written"], st["skipped"], st["errors"]) == (2, 3, 0)
    assert sink.stopped == "max_frames"
    assert len([r for r in caplog.records if "max_frames" in r.getMessage()]) == 1


@pytest.mark.parametrize(("budget_frames", "expect"), [(2.5, 2), (2.0, 2), (0.5, 0)])
def test_max_bytes_is_a_hard_budget(tmp_path, caplog, budget_frames, expect):
    frame = metric_frame()
    size = len(wire.encode_frame(frame, "png"))  # seq 0..4 all encode to the same size
    budget = int(size * budget_frames)
    with (
        caplog.at_level(logging.WARNING, logger="vpp_service.sinks.record"),
        make_sink(tmp_path, max_bytes=budget) as sink,
    ):
        for s in range(5):
            sink.write(as_result(frame.with_(seq=s)))
    files = list(tmp_path.glob("*.msgpack"))
    assert len(files) == expect
    total = sum(p.stat().st_size for p in files)
    assert total == sink.stats()["bytes"] <= budget
    st = sink.stats()
    assert (st["written"], st["skipped"], st["errors"]) == (expect, 5 - expect, 0)
    assert sink.stopped == "max_bytes"
    assert len([r for r in caplog.records if "max_bytes" in r.getMessage()]) == 1


def test_overwrite_false_counts_an_error_and_keeps_the_file(tmp_path):
    existing = tmp_path / "cam_000000000.msgpack"
    existing.write_bytes(b"old")
    with make_sink(tmp_path) as sink:
        sink.write(as_result(metric_frame(0)))  # collides
        sink.write(as_result(metric_frame(1)))  # does not
    assert existing.read_bytes() == b"old"
    st = sink.stats()
    assert (st["written"], st["errors"]) == (1, 1)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cam_000000000.msgpack", "cam_000000001.msgpack"]
    with make_sink(tmp_path, overwrite=True) as sink:
        sink.write(as_result(metric_frame(0)))
    assert sink.stats()["errors"] == 0
    assert existing.read_bytes() == wire.encode_frame(metric_frame(0), "png")


def test_unencodable_frame_is_counted_not_raised(tmp_path):
    bad = metric_frame().with_(right=np.zeros((4, 4), np.uint8))  # left and right differ: no in/frame holds it
    with make_sink(tmp_path) as sink:
        sink.write(as_result(bad))
        sink.write(as_result(metric_frame(1)))
    assert (sink.stats()["errors"], sink.stats()["written"]) == (1, 1)
    assert [p.name for p in tmp_path.iterdir()] == ["cam_000000001.msgpack"]


def test_write_error_after_open_is_counted(tmp_path):
    d = tmp_path / "rec"
    sink = make_sink(d, create_dir=True)
    d.rmdir()  # the folder disappears under a running recorder
    sink.write(as_result(metric_frame()))
    assert sink.stats()["errors"] == 1 and sink.stats()["written"] == 0
    sink.close()


def test_pattern_and_context_rig(tmp_path):
    with make_sink(tmp_path, pattern="{rig}-{stamp_ns:020d}") as sink:
        sink.write(as_result(metric_frame(3).with_(rig="")))
        assert sink.output_path(as_result(metric_frame(3))).name == "cam-00000000000000001003.msgpack"
    (p,) = tmp_path.iterdir()
    assert p.name == "ctxrig-00000000000000001003.msgpack"
    assert wire.decode_frame(p.read_bytes()).rig == "ctxrig"


def test_no_temporary_files_left(tmp_path):
    (tmp_path / "cam_000000000.msgpack").write_bytes(b"old")
    with make_sink(tmp_path) as sink:
        for s in range(3):
            sink.write(as_result(metric_frame(s)))
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_recorded_frames_get_the_umask_mode(tmp_path, umask):
    with make_sink(tmp_path) as sink:
        sink.write(as_result(metric_frame(0)))
    (p,) = tmp_path.iterdir()
    assert stat.S_IMODE(p.stat().st_mode) == 0o666 & ~umask


def test_write_atomic(tmp_path):
    p = tmp_path / "x.msgpack"
    write_atomic(p, b"abc", overwrite=False)
    assert p.read_bytes() == b"abc"
    with pytest.raises(FileExistsError, match="overwrite"):
        write_atomic(p, b"def", overwrite=False)
    write_atomic(p, b"def", overwrite=True)
    assert p.read_bytes() == b"def" and [q.name for q in tmp_path.iterdir()] == ["x.msgpack"]
    with pytest.raises(FileNotFoundError, match=re.escape(str(tmp_path / "missing"))):
        write_atomic(tmp_path / "missing" / "y.msgpack", b"", overwrite=True)


def test_open_and_life_cycle_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"sinks\.record\.dir"):
        make_sink(tmp_path / "missing")
    not_dir = tmp_path / "file"
    not_dir.write_text("x")
    with pytest.raises(NotADirectoryError, match=r"sinks\.record\.dir"):
        make_sink(not_dir)
    with pytest.raises(PermissionError, match="cannot create"):
        make_sink(not_dir / "sub", create_dir=True)
    made = tmp_path / "a" / "b"
    make_sink(made, create_dir=True).close()
    assert made.is_dir()
    sink = build_sink("record", {"dir": str(tmp_path)})
    with pytest.raises(RuntimeError, match="before open"):
        sink.write(as_result(metric_frame()))
    sink.open()
    with pytest.raises(TypeError, match="result"):
        sink.write(metric_frame())
    sink.close()
    with pytest.raises(RuntimeError, match="after close"):
        sink.write(as_result(metric_frame()))
    with pytest.raises(TypeError, match="options"):
        RecordSink({"dir": str(tmp_path)})


@pytest.mark.parametrize(
    ("opts", "key"),
    [
        ({}, "sinks.record"),
        ({"dir": ""}, "dir"),
        ({"dir": "x", "enc": "jpeg"}, "sinks.record.enc"),
        ({"dir": "x", "max_frames": -1}, "max_frames"),
        ({"dir": "x", "max_frames": "10"}, "sinks.record.max_frames"),
        ({"dir": "x", "max_bytes": -5}, "max_bytes"),
        ({"dir": "x", "max_bytes": 1.5}, "sinks.record.max_bytes"),
        ({"dir": "x", "overwrite": "yes"}, "sinks.record.overwrite"),
        ({"dir": "x", "create_dir": 1}, "sinks.record.create_dir"),
        ({"dir": "x", "pattern": "{bogus}"}, "pattern"),
        ({"dir": "x", "pattern": "a/{seq}"}, "pattern"),
        ({"dir": "x", "pattern": ".{seq}"}, "pattern"),
        ({"dir": "x", "formats": ["png16"]}, "sinks.record.formats"),
    ],
)
def test_bad_options_name_the_key(opts, key):
    with pytest.raises(SettingsError) as exc:
        build_sink("record", opts)
    msg = str(exc.value)
    assert msg.startswith("sinks.record") and key in msg, msg


def test_toml_config_validates(tmp_path):
    from vpp_service.service.config import load_config

    p = tmp_path / "rec.toml"
    p.write_text(
        f'[service]\nout = "{tmp_path}/o"\n[zenoh]\nenabled = false\n'
        '[[sinks]]\ntype = "record"\ndir = "{out}/recording"\ncreate_dir = true\nenc = "raw"\n'
        "max_frames = 100\nmax_bytes = 1_000_000_000\noverwrite = false\n"
        'pattern = "{rig}_{seq:09d}"\n'
    )
    cfg = load_config(p)
    (spec,) = cfg.sinks
    assert spec.name == "record"
    o = spec.options
    assert (o.dir, o.create_dir, o.enc, o.max_frames, o.max_bytes, o.overwrite, o.pattern) == (
        f"{tmp_path}/o/recording",
        True,
        "raw",
        100,
        1_000_000_000,
        False,
        "{rig}_{seq:09d}",
    )
    p.write_text('[zenoh]\nenabled = false\n[[sinks]]\ntype = "record"\ndir = "x"\nenc = "jpeg"\n')
    with pytest.raises(SettingsError, match=r"^sinks\[0\]\.enc"):
        load_config(p)


def _service_config(tmp_path, source: dict, rec: str):
    from vpp_service.service.config import validate_config

    return validate_config(
        {
            "service": {"out": str(tmp_path / "out"), "summary": False, "max_frames": 3},
            "zenoh": {"enabled": False},
            "source": source,
            "vpp": {"enabled": False},
            "matcher": {"name": "bm", "max_disparity": 16},
            "queues": {"input_policy": "block", "output_policy": "block"},
            "sinks": [{"type": "record", "dir": rec, "create_dir": True}],
        }
    )


def test_service_records_and_a_second_service_replays(tmp_path):
    """Record a running service's input, replay the recording into a second service, record again."""
    from vpp_service.service.app import run_service

    sim = {
        "type": "sim",
        "scene": "synthetic",
        "rate_hz": 0,
        "count": 3,
        "scene_options": {"height": H, "width": W, "max_disparity": 8},
    }
    first, second = tmp_path / "rec1", tmp_path / "rec2"
    status = run_service(_service_config(tmp_path, sim, str(first)), threading.Event(), None)
    assert status["counters"]["processed"] == 3
    (rec_stats,) = status["sinks"].values()
    assert rec_stats["written"] == 3 and rec_stats["errors"] == 0
    files = {"type": "files", "root": str(first), "format": "msgpack", "sensor": "none"}
    status = run_service(_service_config(tmp_path, files, str(second)), threading.Event(), None)
    assert status["counters"]["processed"] == 3
    names1 = sorted(p.name for p in first.glob("*.msgpack"))
    names2 = sorted(p.name for p in second.glob("*.msgpack"))
    assert names1 == names2 == [f"rig0_{i:09d}.msgpack" for i in range(3)]
    for n in names1:
        a = wire.decode_frame((first / n).read_bytes())
        b = wire.decode_frame((second / n).read_bytes())
        assert a.sparse_disparity is not None and a.gt_disparity is not None
        assert_same_frame(b, a)


@pytest.mark.parametrize("how", [["--dataset", "auto", "--root"], ["--recording"]])
def test_vpp_service_publish_replays_a_recording(tmp_path, zenoh_endpoint, zenoh_config, how):
    """``vpp-service publish --recording REC`` (or ``--dataset auto --root REC``) replays a recording.

    The recorded frames arrive on Zenoh unchanged.
    """
    import zenoh

    from vpp_service.cli import main

    ref = sim_frames(3)
    with make_sink(tmp_path) as sink:
        for f in ref:
            sink.write(as_result(f))
    got: list[StereoFrame] = []
    with zenoh.open(zenoh_config(listen=[zenoh_endpoint])) as session:
        sub = session.declare_subscriber(
            "vpp/front/in/frame", lambda s: got.append(wire.decode_frame(s.payload.to_bytes()))
        )
        handlers = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
        try:  # publish installs its own SIGINT/SIGTERM handlers
            rc = main(
                [
                    "publish",
                    *how,
                    str(tmp_path),
                    "--rate",
                    "0",
                    "--rig",
                    "front",
                    "--enc",
                    "png",
                    "--connect",
                    zenoh_endpoint,
                    "--wait-subscriber",
                    "5",
                ]
            )
        finally:
            for s, h in handlers.items():
                signal.signal(s, h)
        assert rc == 0
        deadline = threading.Event()
        for _ in range(100):
            if len(got) >= 3:
                break
            deadline.wait(0.05)
        sub.undeclare()
    assert [f.seq for f in got] == [0, 1, 2] and all(f.rig == "front" for f in got)
    for g, r in zip(got, ref, strict=True):
        assert_same_frame(g, r)


def test_example_config_documents_the_record_sink():
    """deploy/config.example.toml shows every record option, and its commented block validates."""
    import dataclasses
    import re
    import tomllib
    from pathlib import Path

    from vpp_service.service.config import validate_config
    from vpp_service.sinks.record import RecordSinkOptions

    text = (Path(__file__).resolve().parents[1] / "deploy" / "config.example.toml").read_text()
    start = text.index('# type = "record"')
    block = text[text.rindex("# [[sinks]]", 0, start) :]
    block = block[: block.index("\n\n")] if "\n\n" in block else block
    for f in dataclasses.fields(RecordSinkOptions):
        assert re.search(rf"^# {f.name} = ", block, re.MULTILINE), f"record option {f.name} undocumented"
    uncommented = "\n".join(line[2:] for line in block.splitlines())
    data = tomllib.loads(uncommented)
    assert data["sinks"][0]["type"] == "record"
    cfg = validate_config({"zenoh": {"enabled": False}, "sinks": data["sinks"]})
    assert cfg.sinks[0].options == RecordSinkOptions(dir="vpp-run/recording")  # every value shown is the default


@pytest.mark.parametrize("rig", ["../../x/relative", "/abs/path", "../sibling", ".hidden", "a\x00b", "..", "r/x"])
def test_hostile_rig_records_nothing_and_is_counted(tmp_path, rig):
    sink_dir = tmp_path / "a" / "b" / "rec"
    sink = make_sink(tmp_path, dir=str(sink_dir), create_dir=True, enc="raw")
    sink.write(as_result(metric_frame().with_(rig=rig)))
    assert sink.stats()["errors"] == 1 and sink.stats()["written"] == 0
    assert [p for p in tmp_path.rglob("*") if p.is_file()] == []
