"""rosbag2 source: bags written with rosbags (.mcap and .db3) played into frames; pacing, count, loop, refusals.

Damaged bags (cut short, garbage written in) play every readable frame and count the damage by cause.
"""

from __future__ import annotations

import time

import cv2
import numpy as np
import pytest

from helpers.damaged_bags import STAMPS as STAMPS_20
from helpers.damaged_bags import cut, garble, write_test_bag
from helpers.ros2_robot import StereoRig, write_bag
from vpp_service.settings import SettingsError
from vpp_service.sources.base import SourceContext, build_source, parse_source_options
from vpp_service.transport.ros2.bag import read_bag
from vpp_service.transport.ros2.bag_damage import ignore_damage

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


@pytest.mark.parametrize("codec", ["png", "jpeg"])
def test_compressed_views_played_like_raw_ones(tmp_path, codec):
    rng = np.random.default_rng(1)
    img = cv2.resize(rng.integers(0, 256, (3, 4, 3), dtype=np.uint8), (32, 24), interpolation=cv2.INTER_CUBIC)
    rig = StereoRig(img, img[:, ::-1].copy(), 100.0, 0.1, 15.0, 17.0, 11.0, np.array([[0, 0, 2.0]], np.float32))
    write_bag(str(tmp_path / "bag"), "mcap", rig, STAMPS, compressed=codec)
    frames, rejects, st = play(tmp_path / "bag", transport="compressed")
    assert [f.stamp_ns for f in frames] == STAMPS and not rejects and st["read"] == 15
    for f in frames:
        for got, want in ((f.left, rig.left), (f.right, rig.right)):
            err = np.abs(got.astype(int) - want.astype(int))
            assert got.shape == want.shape and (err.max() == 0 if codec == "png" else err.mean() < 4.0)
        assert f.calib.doffs == 2.0 and f.sensor_depth[11, 15] == pytest.approx(2.0)
    frames, _, st = play(tmp_path / "bag")  # raw transport: image_rect is not in the bag, no set completes
    assert frames == [] and st["messages"]["used"] == 0


@pytest.mark.parametrize("opts", [{}, {"path": "/nonexistent/bag"}, {"path": "x", "rate": -1.0}])
def test_bad_options(tmp_path, opts):
    with pytest.raises(SettingsError):
        parse_source_options("rosbag2", opts)


def test_folder_without_metadata_refused(tmp_path):
    with pytest.raises(SettingsError, match=r"metadata\.yaml"):
        parse_source_options("rosbag2", {"path": str(tmp_path)})


# ------------------------------------------------------------------ damaged bags
@pytest.fixture(scope="module", params=["mcap", "sqlite3"])
def intact_bag(request, tmp_path_factory):
    """(storage file, frames played from it): MCAP with chunk CRCs as ros2 bag record writes them, or sqlite3."""
    f = write_test_bag(tmp_path_factory.mktemp(request.param) / "bag", request.param)
    frames, rejects, _ = play(f)
    assert len(frames) == 20 and not rejects
    return f, frames


def complete_stamps(path) -> set[int]:
    """Stamps whose five messages can all be read (write_bag logs message i of a stamp at stamp + i us)."""
    times = {m.log_time_ns for m in read_bag(path, on_damage=ignore_damage)}
    return {s for s in STAMPS_20 if all(s + i * 1000 in times for i in range(5))}


@pytest.mark.parametrize("damage", ["cut 0.5", "cut 0.9", "cut 0.99", "garbage"])
def test_a_damaged_bag_plays_every_readable_frame_and_counts_the_damage(intact_bag, tmp_path, damage):
    f, ref = intact_bag
    out = tmp_path / f"damaged{f.suffix}"
    bad = garble(f, out) if damage == "garbage" else cut(f, out, float(damage.split()[1]))
    frames, rejects, st = play(bad)
    by_stamp = {fr.stamp_ns: fr for fr in ref}
    assert 0 < len(frames) <= 20 and {fr.stamp_ns for fr in frames} >= complete_stamps(bad)
    for fr in frames:  # bit for bit the frames of the intact bag
        want = by_stamp[fr.stamp_ns]
        assert np.array_equal(fr.left, want.left) and np.array_equal(fr.right, want.right)
        assert np.array_equal(fr.sensor_depth, want.sensor_depth, equal_nan=True)
    causes = st["rejected_by"]
    expected = {"bag.truncated"} if damage != "garbage" else {"bag.crc" if f.suffix == ".mcap" else "bag.corrupt_row"}
    assert set(causes) == expected and st["rejected"] == sum(causes.values()) == len(rejects) >= 1
    assert all(str(bad) in r and ("byte" in r or "row" in r) for r in rejects)


def test_a_looped_damaged_bag_counts_its_damage_once(intact_bag, tmp_path):
    f, _ = intact_bag
    frames, rejects, st = play(cut(f, tmp_path / f"cut{f.suffix}", 0.9), loop=True, count=40)
    assert len(frames) == 40 and st["passes"] >= 2 and st["rejected"] == len(rejects) == sum(st["rejected_by"].values())
    assert len(rejects) == len(play(cut(f, tmp_path / f"once{f.suffix}", 0.9))[1])


def test_a_bag_with_nothing_readable_ends_the_source_with_an_error(intact_bag, tmp_path):
    f, _ = intact_bag
    stub = cut(f, tmp_path / f"stub{f.suffix}", 4096 / f.stat().st_size)
    src = build_source("rosbag2", {"path": str(stub), "rate": 0.0}, SourceContext(rig="b"))
    src.open()
    src.start(lambda f: True, lambda r: None)
    assert src.finished.wait(20.0)
    src.stop(1.0)
    assert isinstance(src.error, ValueError) and str(stub) in str(src.error)
