"""Tests of the ``files`` sink (real files in tmp_path, read back with OpenCV/numpy)."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import cv2
import numpy as np
import pytest

from vpp_service.datasets.pfm import read_pfm
from vpp_service.frame import Calibration, FusionResult, StereoFrame
from vpp_service.settings import SettingsError
from vpp_service.sinks import SINKS, build_sink
from vpp_service.sinks.base import SinkContext
from vpp_service.sinks.files import FilesSink, decode_png16, encode_png16

H, W = 24, 32


@pytest.fixture
def result() -> FusionResult:
    rng = np.random.default_rng(7)
    left = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
    right = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
    disp = rng.uniform(0.5, 200.0, (H, W)).astype(np.float32)
    disp[3, 4] = np.nan
    disp[10, :5] = np.nan
    disp[0, 0] = np.inf
    calib = Calibration(f=500.0, baseline=0.1)
    depth = (calib.f * calib.baseline / disp).astype(np.float32)
    depth[~np.isfinite(disp)] = np.nan
    frame = StereoFrame(left, right, calib, rig="rigA", seq=42, stamp_ns=123, name="scene")
    return FusionResult(frame, disp, depth=depth, left_vpp=left // 2, right_vpp=right // 2)


def make_sink(tmp_path, **opts) -> FilesSink:
    opts.setdefault("dir", str(tmp_path))
    sink = build_sink("files", opts, SinkContext(rig="ctxrig"))
    sink.open()
    return sink


def test_registered():
    assert SINKS.get("files") is FilesSink


def test_png16_round_trip(tmp_path, result):
    sink = make_sink(tmp_path, formats=["png16"])
    sink.write(result)
    path = tmp_path / "rigA_000042_disparity.png"
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    assert img.dtype == np.uint16 and img.shape == (H, W)
    valid = np.isfinite(result.disparity)
    assert np.all(img[~valid] == 0)
    assert np.all(img[valid] > 0)
    err = np.abs(img[valid] / 256.0 - result.disparity[valid])
    assert err.max() <= 1.0 / 256
    back = decode_png16(path.read_bytes())
    assert np.array_equal(np.isnan(back), ~valid)
    assert sink.stats() == {"written": 1, "dropped": 0, "errors": 0, "files": 1}


def test_pfm_round_trip_and_layout(tmp_path, result):
    sink = make_sink(tmp_path, formats=["pfm"])
    sink.write(result)
    path = tmp_path / "rigA_000042_disparity.pfm"
    back = read_pfm(path)
    valid = np.isfinite(result.disparity)
    assert np.array_equal(back[valid], result.disparity[valid])
    assert np.all(np.isposinf(back[~valid]))  # NaN and inf are written as +inf
    raw = path.read_bytes()
    header = b"Pf\n%d %d\n-1\n" % (W, H)
    assert raw.startswith(header)
    rows = np.frombuffer(raw[len(header) :], "<f4").reshape(H, W)
    assert np.array_equal(rows[0], result.disparity[-1])  # stored bottom-up, little-endian


def test_npy_and_depth_round_trip(tmp_path, result):
    sink = make_sink(tmp_path, formats=["npy"], depth=True)
    sink.write(result)
    d = np.load(tmp_path / "rigA_000042_disparity.npy")
    assert d.dtype == np.float32
    valid = np.isfinite(result.disparity)
    assert np.array_equal(np.isnan(d), ~valid)  # inf becomes NaN too
    assert np.array_equal(d[valid], result.disparity[valid])
    z = np.load(tmp_path / "rigA_000042_depth.npy")
    assert np.array_equal(z, result.depth, equal_nan=True)


def test_painted_pngs(tmp_path, result):
    sink = make_sink(tmp_path, formats=["png16"], painted=True)
    sink.write(result)
    for side, img in (("left", result.left_vpp), ("right", result.right_vpp)):
        bgr = cv2.imread(str(tmp_path / f"rigA_000042_{side}_vpp.png"), cv2.IMREAD_COLOR)
        assert np.array_equal(bgr[..., ::-1], img)


@pytest.mark.parametrize("top", [0.0, 400.0])
def test_preview_png_is_colour_mapped_rgb(tmp_path, result, top):
    """The preview is an 8-bit RGB PNG an image viewer shows: turbo over [0, top] (or the frame's range)."""
    from vpp_service.sinks.colorize import colorize_disparity

    sink = make_sink(tmp_path, formats=["png16"], preview=True, preview_max_disparity=top)
    sink.write(result)
    bgr = cv2.imread(str(tmp_path / "rigA_000042_disparity_preview.png"), cv2.IMREAD_UNCHANGED)
    assert bgr.dtype == np.uint8 and bgr.shape == (H, W, 3)
    rgb = bgr[..., ::-1]
    expected = colorize_disparity(result.disparity, 0.0, top) if top else colorize_disparity(result.disparity)
    assert np.array_equal(rgb, expected)
    valid = np.isfinite(result.disparity)
    assert np.all(rgb[~valid] == 0) and rgb[valid].max(axis=-1).min() > 0  # invalid black, valid coloured
    assert sink.stats()["files"] == 2


def test_preview_bad_range():
    with pytest.raises(SettingsError, match="preview_max_disparity"):
        build_sink("files", {"dir": "x", "preview": True, "preview_max_disparity": -1.0})


def test_missing_optional_data_is_skipped(tmp_path, result):
    result.left_vpp = result.right_vpp = result.depth = None
    sink = make_sink(tmp_path, formats=["npy"], painted=True, depth=True)
    sink.write(result)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rigA_000042_disparity.npy"]
    assert sink.stats()["errors"] == 0


def test_all_formats_no_temp_leftovers(tmp_path, result):
    sink = make_sink(tmp_path, formats=["png16", "pfm", "npy"], painted=True, depth=True)
    for seq in range(3):
        result.frame.seq = seq
        sink.write(result)
    sink.close()
    names = sorted(p.name for p in tmp_path.iterdir())
    assert len(names) == 3 * 6
    assert not [n for n in names if n.startswith(".")]
    assert sink.stats()["written"] == 3 and sink.stats()["files"] == 18


def test_every_file_gets_the_umask_mode(tmp_path, result, umask):
    """Every kind of file the sink writes is as readable as the umask allows (0o644 under 022, 0o640 under 027)."""
    sink = make_sink(tmp_path, formats=["png16", "pfm", "npy"], painted=True, depth=True, preview=True)
    sink.write(result)
    modes = {p.name: stat.S_IMODE(p.stat().st_mode) for p in tmp_path.iterdir()}
    assert len(modes) == 7
    assert set(modes.values()) == {0o666 & ~umask}, modes


def test_pattern_and_context_rig(tmp_path, result):
    result.frame.rig = ""
    sink = make_sink(tmp_path, formats=["npy"], pattern="{name}-{rig}-{stamp_ns}")
    paths = sink.output_paths(result)
    assert paths == {"npy": tmp_path / "scene-ctxrig-123_disparity.npy"}
    sink.write(result)
    assert paths["npy"].is_file()


@pytest.mark.parametrize("overwrite", [False, True])
def test_overwrite(tmp_path, result, overwrite):
    sink = make_sink(tmp_path, formats=["npy"], overwrite=overwrite)
    sink.write(result)
    first = result.disparity
    result.disparity = first + 1.0
    sink.write(result)  # errors are counted, never raised
    d = np.load(tmp_path / "rigA_000042_disparity.npy")
    expected = result.disparity if overwrite else first
    valid = np.isfinite(expected)
    assert np.array_equal(d[valid], expected[valid]) and np.all(np.isnan(d[~valid]))
    assert sink.stats()["errors"] == (0 if overwrite else 1)
    assert sink.stats()["written"] == (2 if overwrite else 1)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_bad_result_arrays_are_counted(tmp_path, result):
    result.disparity = np.zeros((H, W, 2), np.float32)
    sink = make_sink(tmp_path, formats=["png16", "pfm", "npy"])
    sink.write(result)
    assert sink.stats()["errors"] == 3 and sink.stats()["written"] == 0
    assert list(tmp_path.iterdir()) == []


def test_write_type_and_state_errors(tmp_path, result):
    sink = build_sink("files", {"dir": str(tmp_path)})
    with pytest.raises(RuntimeError, match="before open"):
        sink.write(result)
    sink.open()
    with pytest.raises(TypeError, match="result"):
        sink.write("not a result")


def test_open_missing_dir(tmp_path):
    sink = build_sink("files", {"dir": str(tmp_path / "nope")})
    with pytest.raises(FileNotFoundError, match=r"sinks\.files\.dir.*does not exist"):
        sink.open()


def test_open_create_dir(tmp_path, result):
    sink = make_sink(tmp_path, dir=str(tmp_path / "a" / "b"), create_dir=True, formats=["npy"])
    sink.write(result)
    assert (tmp_path / "a" / "b" / "rigA_000042_disparity.npy").is_file()


def test_open_not_a_dir(tmp_path):
    f = tmp_path / "file"
    f.write_text("x")
    with pytest.raises(NotADirectoryError, match=r"sinks\.files\.dir"):
        build_sink("files", {"dir": str(f)}).open()


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() == 0, reason="root can write anywhere")
def test_open_unwritable_dir(tmp_path):
    d = tmp_path / "ro"
    d.mkdir(mode=0o500)
    with pytest.raises(PermissionError, match="not writable"):
        build_sink("files", {"dir": str(d)}).open()


@pytest.mark.parametrize(
    ("opts", "key"),
    [
        ({}, "dir"),
        ({"dir": ""}, "dir"),
        ({"dir": "x", "formats": ["tiff"]}, "formats[0]"),
        ({"dir": "x", "formats": []}, "formats"),
        ({"dir": "x", "formats": ["npy", "npy"]}, "formats"),
        ({"dir": "x", "formats": "npy"}, "formats"),
        ({"dir": "x", "pattern": "{bogus}"}, "pattern"),
        ({"dir": "x", "pattern": "a/{seq}"}, "pattern"),
        ({"dir": "x", "overwrite": "yes"}, "overwrite"),
        ({"dir": "x", "colour": True}, "colour"),
    ],
)
def test_bad_options(opts, key):
    with pytest.raises(SettingsError, match=rf"sinks\.files.*{key.replace('[', '.').replace(']', '.')}"):
        build_sink("files", opts)


def test_encode_png16_reference():
    d = np.array([[np.nan, 0.0, -1.0, 1e-4], [1.0, 2.5, 255.99, 300.0]], np.float32)
    img = cv2.imdecode(np.frombuffer(encode_png16(d), np.uint8), cv2.IMREAD_UNCHANGED)
    expected = np.array([[0, 0, 0, 1], [256, 640, 65533, 65535]], np.uint16)
    assert np.array_equal(img, expected)


@pytest.mark.parametrize(
    ("bad", "exc"),
    [
        ("x", TypeError),
        (np.zeros((2, 2), bool), TypeError),
        (np.zeros((2, 2, 2)), ValueError),
        (np.zeros((0, 3)), ValueError),
    ],
)
def test_encode_png16_errors(bad, exc):
    with pytest.raises(exc, match="disparity"):
        encode_png16(bad)


@pytest.mark.parametrize("bad", [b"", b"not a png", cv2.imencode(".png", np.zeros((2, 2), np.uint8))[1].tobytes()])
def test_decode_png16_errors(bad):
    with pytest.raises(ValueError, match="data"):
        decode_png16(bad)


@pytest.mark.parametrize("rig", ["../../x/relative", "/abs/path", "../sibling", ".hidden", "a\x00b", "..", "r/x"])
def test_hostile_rig_writes_nothing_and_is_counted(tmp_path, result, rig):
    sink_dir = tmp_path / "a" / "b" / "sink"
    sink = make_sink(tmp_path, dir=str(sink_dir), create_dir=True, formats=["png16", "npy"], depth=True, painted=True)
    sink.write(with_rig(result, rig))
    assert sink.stats()["errors"] == 1 and sink.stats()["written"] == 0
    assert [p for p in tmp_path.rglob("*") if p.is_file()] == []
    assert not Path("/abs/path").exists()


def with_rig(result: FusionResult, rig: str) -> FusionResult:
    """``result`` with its frame's rig replaced (as a message could set it)."""
    return FusionResult(
        result.frame.with_(rig=rig),
        result.disparity,
        depth=result.depth,
        left_vpp=result.left_vpp,
        right_vpp=result.right_vpp,
    )


def test_example_config_documents_the_files_sink():
    """deploy/config.example.toml shows every files-sink option (depth, painted ...), and its block validates."""
    import dataclasses
    import re
    import tomllib

    from vpp_service.service.config import validate_config
    from vpp_service.sinks.files import FilesSinkOptions

    text = (Path(__file__).resolve().parents[1] / "deploy" / "config.example.toml").read_text()
    start = text.index('# type = "files"')
    block = text[text.rindex("# [[sinks]]", 0, start) :]
    block = block[: block.index("\n\n")]
    for f in dataclasses.fields(FilesSinkOptions):
        assert re.search(rf"^# {f.name} = ", block, re.MULTILINE), f"files option {f.name} undocumented"
    data = tomllib.loads("\n".join(line[2:] for line in block.splitlines()))
    cfg = validate_config({"zenoh": {"enabled": False}, "sinks": data["sinks"]})
    # every value shown is the default, but for the folder the example names and creates
    assert cfg.sinks[0].options == FilesSinkOptions(dir="vpp-run/frames", create_dir=True)


# -- points: <stem>_points.ply ------------------------------------------------------------


@pytest.mark.parametrize("stride", [1, 3])
def test_points_written_as_ply_and_read_back(tmp_path, stride):
    from helpers.points import assert_cloud_is_depth, clipped_result, read_ply

    res = clipped_result(seq=9)
    sink = make_sink(tmp_path, points=True, points_stride=stride)
    assert FilesSink.needs_depth(sink.options)
    sink.write(res)
    sink.close()
    path = tmp_path / "r1_000009_points.ply"
    comments, v = read_ply(path.read_bytes())
    assert "vpp-service rig r1 seq 9 stamp_ns 1000009" in comments
    xyz = np.stack([v["x"], v["y"], v["z"]], axis=1)
    rgb = np.stack([v["r"], v["g"], v["b"]], axis=1)
    assert_cloud_is_depth(xyz, rgb, res, stride)
    assert sink.stats()["errors"] == 0 and not list(tmp_path.glob(".*"))  # written atomically, no temp left


def test_points_skipped_without_metric_depth(tmp_path, result):
    sink = make_sink(tmp_path, points=True)
    sink.write(FusionResult(result.frame.with_(calib=None), result.disparity, depth=None))
    sink.close()
    assert not list(tmp_path.glob("*_points.ply")) and sink.stats()["errors"] == 0


@pytest.mark.parametrize("bad", [0, 65, "2", 1.5])
def test_bad_points_stride(tmp_path, bad):
    with pytest.raises(SettingsError, match=r"sinks\.files.*points_stride"):
        make_sink(tmp_path, points=True, points_stride=bad)


def test_confidence_npy_and_png16(tmp_path, result):
    """The files sink with confidence = true: the float32 map as .npy, and a 16-bit PNG scaled to 65535."""
    conf = np.random.default_rng(1).random((H, W), dtype=np.float32)
    conf[3, 4] = 0.0
    result.confidence = conf
    sink = make_sink(tmp_path, formats=["npy"], confidence=True)
    assert FilesSink.needs_confidence(sink.options) and not FilesSink.needs_confidence(make_sink(tmp_path).options)
    sink.write(result)
    np.testing.assert_array_equal(np.load(tmp_path / "rigA_000042_confidence.npy"), conf)
    png = cv2.imread(str(tmp_path / "rigA_000042_confidence.png"), cv2.IMREAD_UNCHANGED)
    assert png.dtype == np.uint16 and png.shape == (H, W) and png[3, 4] == 0
    assert np.abs(png / 65535.0 - conf).max() <= 0.5 / 65535 + 1e-9
    result.confidence = None  # not computed: nothing written, nothing counted as an error
    sink.write(result.__class__(result.frame.with_(seq=43), result.disparity))
    assert not (tmp_path / "rigA_000043_confidence.npy").exists()
    assert sink.stats()["errors"] == 0
