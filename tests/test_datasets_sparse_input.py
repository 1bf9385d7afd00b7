"""A frame's own sparse depth (``sparse/`` of the folder layout): each form read back, bad files named."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from helpers.own_folder import own_scene, sparse_points, write_sparse
from vpp_service.datasets.sparse_input import read_sparse
from vpp_service.frame import Calibration


@pytest.fixture(scope="module")
def scene():
    frame = own_scene(0.25)
    return frame, sparse_points(frame)


@pytest.mark.parametrize("ext", [".png", ".npy", ".csv", ".txt"])
def test_every_form_reads_back_the_same_points(tmp_path, scene, ext):
    frame, sparse = scene
    path = tmp_path / f"000{ext}"
    write_sparse(path, sparse)
    got, lidar_like = read_sparse(path, frame.shape, None)
    assert got.dtype == np.float32 and got.shape == frame.shape and lidar_like is False
    np.testing.assert_array_equal(np.isnan(got), np.isnan(sparse))
    np.testing.assert_allclose(got[~np.isnan(got)], sparse[~np.isnan(sparse)], atol=1e-6)
    assert np.count_nonzero(~np.isnan(got)) > 0.03 * got.size


def test_png_scale_is_the_folder_disp_scale(tmp_path):
    png = np.zeros((4, 5), np.uint16)
    png[1, 2] = 300
    cv2.imwrite(str(tmp_path / "a.png"), png)
    got, _ = read_sparse(tmp_path / "a.png", (4, 5), None, disp_scale=100.0)
    assert got[1, 2] == pytest.approx(3.0) and np.count_nonzero(~np.isnan(got)) == 1


def test_xyz_points_project_with_the_calibration(tmp_path):
    """Metric points land where the pinhole puts them, with d = f b / z - doffs; the nearest wins a pixel."""
    calib = Calibration(f=50.0, baseline=0.2, doffs=1.0, cx=10.0, cy=6.0)
    rows = [
        (0.4, -0.2, 2.0),  # u = 50*0.2 + 10 = 20, v = 50*-0.1 + 6 = 1; d = 5 - 1 = 4
        (0.8, -0.4, 4.0),  # the same pixel, farther (d = 1.5): hidden
        (0.0, 0.0, 5.0),  # the principal point, d = 2 - 1 = 1
        (0.0, 0.0, -3.0),  # behind the camera: dropped
        (9.0, 0.0, 1.0),  # outside the image (u = 460): dropped
    ]
    path = tmp_path / "s.csv"
    path.write_text("x y z\n" + "".join(f"{x} {y} {z}\n" for x, y, z in rows))
    got, lidar_like = read_sparse(path, (12, 24), calib)
    assert lidar_like is True
    assert got[1, 20] == pytest.approx(4.0) and got[6, 10] == pytest.approx(1.0)
    assert np.count_nonzero(~np.isnan(got)) == 2


@pytest.mark.parametrize(
    ("name", "content", "message"),
    [
        ("a.csv", "u,v,d\n1,2,3\n4,nan,2\n", "line 3: a non-finite number"),
        ("a.csv", "u,v,d\n1,2,3\n40,2,2\n", "line 3: a point outside the 24x12 image"),
        ("a.csv", "u,v,d\n1,2,-3\n", "line 2: disparity must be > 0"),
        ("a.txt", "a b c\n1 2 3\n", "header 'a b c'"),
        ("a.txt", "u v d\n1 2\n", "a.txt"),
        ("a.txt", "x y z\n1 2 3\n", "need the folder's calib.json"),
        ("a.csv", "# only a comment\n", "is empty"),
    ],
)
def test_bad_points_files_are_named(tmp_path, name, content, message):
    (tmp_path / name).write_text(content)
    with pytest.raises(ValueError, match="sparse: ") as exc:
        read_sparse(tmp_path / name, (12, 24), None)
    assert message in str(exc.value)


def test_bad_maps_are_named(tmp_path):
    np.save(tmp_path / "small.npy", np.ones((11, 24), np.float32))
    with pytest.raises(ValueError, match=r"small\.npy is 11x24 \(rows x columns\), the images are 12x24"):
        read_sparse(tmp_path / "small.npy", (12, 24), None)
    cv2.imwrite(str(tmp_path / "wide.png"), np.ones((12, 25), np.uint16))
    with pytest.raises(ValueError, match=r"wide\.png is 12x25"):
        read_sparse(tmp_path / "wide.png", (12, 24), None)
    cv2.imwrite(str(tmp_path / "rgb.png"), np.ones((12, 24, 3), np.uint8))
    with pytest.raises(ValueError, match="single-channel"):
        read_sparse(tmp_path / "rgb.png", (12, 24), None)
    inf = np.zeros((12, 24), np.float32)
    inf[3, 4] = np.inf
    np.save(tmp_path / "inf.npy", inf)
    with pytest.raises(ValueError, match=r"inf\.npy holds 1 infinite or negative values \(first at row 3, column 4"):
        read_sparse(tmp_path / "inf.npy", (12, 24), None)
    (tmp_path / "junk.npy").write_bytes(b"not numpy")
    with pytest.raises(ValueError, match="cannot read"):
        read_sparse(tmp_path / "junk.npy", (12, 24), None)
    with pytest.raises(FileNotFoundError, match=r"gone\.png"):
        read_sparse(tmp_path / "gone.png", (12, 24), None)
