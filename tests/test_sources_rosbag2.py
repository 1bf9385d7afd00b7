"""rosbag2 source: bags written with rosbags (.mcap and .db3) played into frames; pacing, count, loop, refusals."""

from __future__ import annotations

import time

import numpy as np
import pytest

from helpers.ros2_robot import StereoRig, write_bag
from vpp_service.settings import SettingsError
from vpp_service.sources.base import SourceContext, build_source, parse_source_options

STAMPS = [1_000_000_000, 1_100_000_000, 1_200_000_000]


def tiny_rig() -> StereoRig:
    rng = np.random.default_rng(0)
    img = rng.integers(0, 256, (6, 8, 3), dtype=np.uint8)
    return StereoRig(img, img, 100.0, 0.1, 3.5, 5.5, 2.5, np.array([[0, 0, 2.0], [0, 0, -1.0]], np.float32))


def play(path, **opts) -> tuple[list, list, dict]:
    src = build_source("rosbag2", {"path": str(path), "rate": 0.0, **opts}, SourceContext(rig="b"))
    frames, rejects = [], []
    src.open()
    src.start(lambda f: frames.append(f) or True, rejects.append)
    assert src.finished.wait(20.0)
    src.stop(1.0)
    return frames, rejects, src.stats()


@pytest.mark.parametrize(("storage", "suffix"), [("mcap", ".mcap"), ("sqlite3", ".db3")])
def test_both_storages_folder_and_file(tmp_path, storage, suffix):
    write_bag(str(tmp_path / "bag"), storage, tiny_rig(), STAMPS)
    for path in (tmp_path / "bag", next((tmp_path / "bag").glob(f"*{suffix}"))):
        frames, rejects, st = play(path)
        assert [f.stamp_ns for f in frames] == STAMPS and not rejects
        assert all(f.sensor_depth[2, 4] == pytest.approx(2.0) for f in frames)
        assert frames[0].calib.doffs == 2.0 and frames[0].meta["ros"]["frame_id"] == "left_optical"
        assert st["read"] == 15 and st["cloud_behind"] == 3 and st["no_depth"] == 0


def test_count_loop_and_rate(tmp_path):
    write_bag(str(tmp_path / "bag"), "mcap", tiny_rig(), STAMPS)
    frames, _, st = play(tmp_path / "bag", loop=True, count=5)
    assert len(frames) == 5 and st["passes"] >= 1
    t0 = time.monotonic()
    frames, _, _ = play(tmp_path / "bag", rate=2.0)  # 0.2 s of recording at 2x
    assert len(frames) == 3 and time.monotonic() - t0 >= 0.09


def test_wrong_type_refused(tmp_path):
    write_bag(str(tmp_path / "bag"), "mcap", tiny_rig(), STAMPS)
    frames, rejects, st = play(tmp_path / "bag", depth_type="image")  # points is a PointCloud2, not an Image
    assert st["rejected_by"] == {"type": 3} and any("PointCloud2" in r for r in rejects)
    assert len(frames) == 3 and all(f.sensor_depth is None for f in frames) and st["no_depth"] == 3


@pytest.mark.parametrize("opts", [{}, {"path": "/nonexistent/bag"}, {"path": "x", "rate": -1.0}])
def test_bad_options(tmp_path, opts):
    with pytest.raises(SettingsError):
        parse_source_options("rosbag2", opts)


def test_folder_without_metadata_refused(tmp_path):
    with pytest.raises(SettingsError, match=r"metadata\.yaml"):
        parse_source_options("rosbag2", {"path": str(tmp_path)})
