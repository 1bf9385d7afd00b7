"""sim and files sources: frames, seq/seed per frame, pacing, count/loop, bad files rejected."""

from __future__ import annotations

import time

import numpy as np
import pytest

from helpers.own_folder import own_scene, write_own_folder
from helpers.shared_data import need_shared
from vpp_service.settings import SettingsError
from vpp_service.sources.base import Pacer, SourceContext, build_source
from vpp_service.sources.sim import MOTORCYCLE_CALIB, motorcycle_frame, scale_frame
from vpp_service.transport import wire


def drain(src, timeout=20.0):
    frames, rejects = [], []
    src.open()
    src.start(lambda f: frames.append(f) or True, rejects.append)
    assert src.finished.wait(timeout)
    src.stop(1.0)
    return frames, rejects


def test_motorcycle_default_frame():
    fr = motorcycle_frame()
    assert fr.left.shape == (500, 741, 3) and fr.calib == MOTORCYCLE_CALIB
    assert np.isnan(fr.gt_disparity).mean() == pytest.approx(0.0735, abs=0.01)  # +inf became NaN


def test_scale_frame_scales_disparity_and_calib():
    fr = motorcycle_frame()
    half = scale_frame(fr, 0.5)
    assert half.left.shape[:2] == (250, 370)
    sx = 370 / 741
    assert half.calib.f == pytest.approx(fr.calib.f * sx) and half.calib.baseline == fr.calib.baseline
    assert np.nanmax(half.gt_disparity) == pytest.approx(np.nanmax(fr.gt_disparity) * sx, rel=0.02)
    with pytest.raises(ValueError, match="scale"):
        scale_frame(fr, 1.5)


def test_sim_default_motorcycle_uniform_5_percent():
    src = build_source("sim", {"scale": 0.5, "rate_hz": 0, "count": 3}, SourceContext(rig="r9"))
    frames, rejects = drain(src)
    assert [f.seq for f in frames] == [0, 1, 2] and not rejects
    for f in frames:
        assert f.rig == "r9" and f.stamp_ns > 0
        valid = np.isfinite(f.gt_disparity)
        pts = np.isfinite(f.sparse_disparity) & (f.sparse_disparity > 0)
        assert pts.sum() / valid.sum() == pytest.approx(0.05, rel=0.05)
        np.testing.assert_allclose(f.sparse_disparity[pts], f.gt_disparity[pts], atol=1e-4)  # noise-free sensor
    assert not np.array_equal(np.isfinite(frames[0].sparse_disparity), np.isfinite(frames[1].sparse_disparity))
    assert frames[1].stamp_ns >= frames[0].stamp_ns


def test_sim_rate_is_paced():
    src = build_source(
        "sim",
        {
            "scene": "synthetic",
            "scene_options": {"height": 32, "width": 64, "max_disparity": 8},
            "rate_hz": 50,
            "count": 6,
        },
        SourceContext(),
    )
    t0 = time.monotonic()
    frames, _ = drain(src)
    assert len(frames) == 6
    assert time.monotonic() - t0 >= 5 / 50 * 0.9


def test_pacer_zero_rate_and_errors():
    src = build_source("sim", {"count": 1}, SourceContext())
    assert Pacer(0).wait(src) is False
    with pytest.raises(ValueError, match="rate_hz"):
        Pacer(-1)


@pytest.mark.parametrize(
    ("opts", "key"),
    [
        ({"scale": 0}, "source.sim"),
        ({"rate_hz": -1}, "source.sim"),
        ({"scene": "moon"}, "source.sim.scene"),
        ({"scene": "dataset"}, "source.sim"),
        ({"count": "3"}, "source.sim.count"),
    ],
)
def test_sim_bad_options(opts, key):
    with pytest.raises(SettingsError) as exc:
        build_source("sim", opts)
    assert str(exc.value).startswith(key)


@pytest.fixture
def msgpack_folder(tmp_path):
    src = build_source(
        "sim",
        {
            "scene": "synthetic",
            "scene_options": {"height": 32, "width": 64, "max_disparity": 8},
            "rate_hz": 0,
            "count": 3,
        },
        SourceContext(),
    )
    src.open()
    frames = [src.frame(i) for i in range(3)]
    for i, fr in enumerate(frames):
        (tmp_path / f"{i:03d}.msgpack").write_bytes(wire.encode_frame(fr))
    return tmp_path, frames


def test_files_msgpack_replay(msgpack_folder):
    folder, ref = msgpack_folder
    frames, rejects = drain(build_source("files", {"root": str(folder), "format": "msgpack"}))
    assert [f.seq for f in frames] == [0, 1, 2] and not rejects
    for f, r in zip(frames, ref, strict=True):
        np.testing.assert_array_equal(f.left, r.left)
        np.testing.assert_array_equal(f.gt_disparity, r.gt_disparity)


def test_files_loop_and_count(msgpack_folder):
    folder, _ = msgpack_folder
    frames, _ = drain(build_source("files", {"root": str(folder), "format": "msgpack", "loop": True, "count": 7}))
    assert [f.seq for f in frames] == list(range(7))


def test_files_bad_file_rejected_and_skipped(msgpack_folder):
    folder, _ = msgpack_folder
    (folder / "001.msgpack").write_bytes(b"\x81\xa1v\x02")
    frames, rejects = drain(build_source("files", {"root": str(folder), "format": "msgpack"}))
    assert len(frames) == 2 and len(rejects) == 1 and "001.msgpack" in rejects[0]


def test_files_directory_named_msgpack_is_skipped(msgpack_folder):
    """A folder named like a frame is counted and skipped; the frames after it are replayed (it ended the run)."""
    folder, _ = msgpack_folder
    (folder / "000b.msgpack").mkdir()
    src = build_source("files", {"root": str(folder), "format": "msgpack"})
    frames, rejects = drain(src)
    assert [f.seq for f in frames] == [0, 1, 2]
    assert len(rejects) == 1 and "000b.msgpack" in rejects[0] and src.stats()["rejected"] == 1
    assert src.error is None


def test_files_corrupt_dataset_image_is_skipped(tmp_path):
    """A corrupt image in a folder dataset is counted and skipped; the other pairs are replayed."""
    import cv2

    rng = np.random.default_rng(0)
    for side in ("left", "right"):
        (tmp_path / side).mkdir()
        for i in range(3):
            cv2.imwrite(str(tmp_path / side / f"{i:03d}.png"), rng.integers(0, 256, (24, 32, 3), dtype=np.uint8))
    (tmp_path / "left" / "001.png").write_bytes(b"\x89PNG\r\n\x1a\n not really")
    src = build_source("files", {"root": str(tmp_path), "dataset": "folder", "sensor": "none"})
    frames, rejects = drain(src)
    assert len(frames) == 2 and len(rejects) == 1 and "[1]" in rejects[0]
    assert src.error is None


def test_files_errors(tmp_path):
    with pytest.raises(SettingsError, match="root"):
        build_source("files", {})
    with pytest.raises(FileNotFoundError, match=r"source\.root"):
        build_source("files", {"root": str(tmp_path / "nope")}).open()
    with pytest.raises(ValueError, match="msgpack"):
        build_source("files", {"root": str(tmp_path), "format": "msgpack"}).open()


def test_files_dataset_reader():
    root = need_shared("middlebury2003_quartersize")
    frames, _ = drain(build_source("files", {"root": str(root), "count": 2, "scale": 0.5}))
    assert len(frames) == 2
    for f in frames:
        pts = np.isfinite(f.sparse_disparity) & (f.sparse_disparity > 0)
        assert pts.any() and np.allclose(f.sparse_disparity[pts], f.gt_disparity[pts], atol=1e-3)


def test_files_replays_own_sparse_depth_without_ground_truth(tmp_path):
    """A folder with sparse/ and no disp/: each frame keeps its own points (no simulated sensor is drawn)."""
    maps = write_own_folder(tmp_path, own_scene(0.25))
    src = build_source("files", {"root": str(tmp_path)})  # the default sensor: uniform 5 %
    frames, rejects = drain(src)
    assert rejects == [] and len(frames) == 3
    for f, want in zip(frames, maps, strict=True):
        assert f.gt_disparity is None and "sensor" not in f.meta
        np.testing.assert_allclose(f.sparse_disparity, want, atol=1e-6)


@pytest.mark.parametrize(
    ("damage", "cause"),
    [
        ("missing", "no sparse input for frame '001'"),
        ("wrong size", "001.npy is 31x45 (rows x columns), the images are 31x46"),
        ("nan", "001.csv line 3: a non-finite number"),
    ],
)
def test_files_bad_sparse_file_rejects_that_frame_only(tmp_path, damage, cause):
    forms = ("png", "csv", "png") if damage == "nan" else ("png", "npy", "png")
    frame = own_scene(0.0625)
    write_own_folder(tmp_path, frame, forms=forms)
    bad = tmp_path / "sparse" / f"001.{forms[1]}"
    if damage == "missing":
        bad.unlink()
    elif damage == "wrong size":
        np.save(bad, np.ones((frame.shape[0], frame.shape[1] - 1), np.float32))
    else:
        lines = bad.read_text().splitlines()
        lines[2] = "3,4,nan"  # the first point, after the comment and the header
        bad.write_text("\n".join(lines) + "\n")
    src = build_source("files", {"root": str(tmp_path)})
    frames, rejects = drain(src)
    assert [f.name for f in frames] == ["000", "002"] and [f.seq for f in frames] == [0, 1]
    assert len(rejects) == 1 and "[1] (001)" in rejects[0] and cause in rejects[0], rejects
    assert src.stats()["rejected"] == 1 and src.error is None


def test_scale_frame_moves_sparse_points():
    """Resizing keeps every sparse point that has a pixel of its own, at its position; disparity scales with width."""
    fr = own_scene(0.5)
    sparse = np.full(fr.shape, np.nan, np.float32)
    sparse[10, 20], sparse[100, 300] = 30.0, 12.0
    sparse[101, 301] = 40.0  # lands on the same half-size pixel as (100, 300): the nearer one wins
    depth = np.zeros(fr.shape, np.float32)
    depth[10, 20], depth[100, 300], depth[101, 301] = 2.0, 5.0, 1.5
    half = scale_frame(fr.with_(sparse_disparity=sparse, sensor_depth=depth), 0.5)
    sx = half.shape[1] / fr.shape[1]
    got = np.argwhere(np.isfinite(half.sparse_disparity))
    assert got.tolist() == [[5, 10], [50, 150]]
    assert half.sparse_disparity[5, 10] == pytest.approx(30.0 * sx) and half.sparse_disparity[50, 150] == pytest.approx(
        40.0 * sx
    )
    assert half.sensor_depth[5, 10] == 2.0 and half.sensor_depth[50, 150] == 1.5
    assert np.count_nonzero(np.isfinite(half.sensor_depth)) == 2
