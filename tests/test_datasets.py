"""Dataset readers on the real benchmark files and on small layouts written to tmp_path."""

from __future__ import annotations

import logging
from pathlib import Path

import cv2
import numpy as np
import pytest

from helpers.own_folder import own_scene, write_own_folder
from helpers.shared_data import need_shared
from vpp_service.datasets import AUTO_ORDER, DATASETS, Dataset, open_dataset, read_pfm, write_pfm
from vpp_service.datasets.base import reader_class
from vpp_service.datasets.calibfile import parse_kitti_calib, parse_middlebury_calib
from vpp_service.datasets.nocc import lr_consistency_mask
from vpp_service.datasets.velodyne import project_points, read_velodyne_bin, velo_to_camera
from vpp_service.frame import StereoFrame

# folder, expected reader, scene count, (H, W) of the first scene, gray?
REAL = [
    ("middlebury2005_2006_thirdsize", "middlebury2006", 26, (370, 427), False),
    ("middlebury2003_quartersize", "middlebury2003", 2, (375, 450), False),
    ("middlebury2001", "middlebury2001", 6, (288, 384), False),
    ("eth3d_two_view_training", "eth3d", 1, (490, 941), False),
    ("kitti2012_training", "kitti2012", 1, (376, 1241), True),
]


def need(folder: str) -> Path:
    return need_shared(folder)


def warp_error(frame: StereoFrame, gt: np.ndarray) -> float:
    """Mean |left - right warped by gt| at valid (non-occluded) pixels, view means removed."""
    h, w = gt.shape
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    g = np.where(np.isfinite(gt), gt, 0).astype(np.float32)
    m = np.isfinite(gt) & (xs - g >= 0)
    if frame.nocc_mask is not None:
        m &= frame.nocc_mask
    left = frame.left.astype(np.float32)
    right = frame.right.astype(np.float32)
    if left.ndim == 3:
        left, right = left.mean(-1), right.mean(-1)
    warped = cv2.remap(right, xs - g, ys, cv2.INTER_LINEAR)
    a, b = left[m], warped[m]
    return float(np.abs((a - a.mean()) - (b - b.mean())).mean())


# ---------------------------------------------------------------- PFM


@pytest.mark.parametrize("shape", [(5, 7), (4, 3, 3)])
def test_pfm_round_trip(tmp_path, shape):
    a = np.random.default_rng(0).normal(size=shape).astype(np.float32)
    a.flat[0] = np.inf
    write_pfm(tmp_path / "a.pfm", a)
    b = read_pfm(tmp_path / "a.pfm")
    assert b.dtype == np.float32 and b.shape == shape
    np.testing.assert_array_equal(a, b)


def test_pfm_big_endian_and_bottom_up(tmp_path):
    # hand-written file: positive scale = big-endian; first stored row is the image's last row
    rows_bottom_up = np.array([[1, 2, 3], [4, 5, 6]], dtype=">f4")
    (tmp_path / "b.pfm").write_bytes(b"Pf\n3 2\n1.0\n" + rows_bottom_up.tobytes())
    np.testing.assert_array_equal(read_pfm(tmp_path / "b.pfm"), [[4, 5, 6], [1, 2, 3]])


def test_pfm_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="path"):
        read_pfm(tmp_path / "missing.pfm")
    (tmp_path / "bad.pfm").write_bytes(b"P6\n1 1\n255\n\0\0\0")
    with pytest.raises(ValueError, match="not a PFM"):
        read_pfm(tmp_path / "bad.pfm")
    (tmp_path / "short.pfm").write_bytes(b"Pf\n4 4\n-1\n" + b"\0" * 8)
    with pytest.raises(ValueError, match="truncated"):
        read_pfm(tmp_path / "short.pfm")
    with pytest.raises(ValueError, match="array"):
        write_pfm(tmp_path / "x.pfm", np.zeros((2, 2, 2), np.float32))
    with pytest.raises(TypeError, match="array"):
        write_pfm(tmp_path / "x.pfm", [[1.0]])


# ---------------------------------------------------------------- real data


@pytest.mark.parametrize(("folder", "reader", "count", "shape", "gray"), REAL)
def test_auto_detects_real_layouts(folder, reader, count, shape, gray):
    ds = open_dataset("auto", need(folder))
    assert ds.name == reader
    assert len(ds) == count == len(ds.scenes)
    f = ds[0]
    assert isinstance(f, StereoFrame)
    assert f.left.dtype == np.uint8 and f.left.shape == f.right.shape
    assert f.left.shape[:2] == shape and (f.left.ndim == 2) == gray
    assert f.gt_disparity.dtype == np.float32 and f.gt_disparity.shape == shape
    assert np.nanmin(f.gt_disparity) > 0 and np.isfinite(f.gt_disparity).any()
    assert f.name == ds.scenes[0]
    assert f.meta["dataset"] == reader and Path(f.meta["path"]).exists()


@pytest.mark.parametrize(
    ("folder", "scene"),
    [
        ("middlebury2005_2006_thirdsize", "Art"),
        ("middlebury2005_2006_thirdsize", "Wood2"),
        ("middlebury2003_quartersize", "Teddy"),
        ("middlebury2001", "Tsukuba"),
        ("middlebury2001", "Venus"),
        ("eth3d_two_view_training", "playground_1l"),
        ("kitti2012_training", "000070/000070_10"),
    ],
)
def test_ground_truth_scale_aligns_views(folder, scene):
    """Warping the right view by the decoded GT matches the left; a wrong scale does not."""
    frame = open_dataset("auto", need(folder))[scene]
    gt = frame.gt_disparity
    good = warp_error(frame, gt)
    for wrong in (1.25, 0.8):
        assert good < 0.8 * warp_error(frame, gt * wrong), (good, wrong)


def test_middlebury2006_scale_option_and_nocc():
    root = need("middlebury2005_2006_thirdsize")
    f3 = open_dataset("middlebury2006", root).select(["Art"])[0]
    f1 = open_dataset("middlebury2006", root, scale=1)[1]
    assert f1.name == "Art"
    np.testing.assert_allclose(f1.gt_disparity, f3.gt_disparity * 3, rtol=1e-6)
    raw = cv2.imread(str(root / "Art" / "disp1.png"), cv2.IMREAD_UNCHANGED)
    assert np.array_equal(np.isnan(f3.gt_disparity), raw == 0)
    m = f3.nocc_mask
    assert m.dtype == bool and 0.6 < m.mean() < np.isfinite(f3.gt_disparity).mean()
    assert not (m & np.isnan(f3.gt_disparity)).any()


def test_middlebury2001_tsukuba_decoding_and_mask():
    root = need("middlebury2001")
    f = open_dataset("middlebury2001", root)["Tsukuba"]
    raw = cv2.imread(str(root / "Tsukuba" / "truedisp.pgm"), cv2.IMREAD_UNCHANGED)
    np.testing.assert_array_equal(f.gt_disparity[raw > 0], raw[raw > 0] / 16.0)
    nonocc = cv2.imread(str(root / "Tsukuba" / "nonocc.png"), cv2.IMREAD_GRAYSCALE)
    np.testing.assert_array_equal(f.nocc_mask, (nonocc == 255) & (raw > 0))
    assert f.meta["scale"] == 16.0 and open_dataset("middlebury2001", root)["Venus"].meta["scale"] == 8.0


def test_middlebury2001_skips_jpeg_scene_with_warning(caplog):
    root = need("middlebury2001")
    with caplog.at_level(logging.WARNING):
        ds = open_dataset("middlebury2001", root)
    assert "bull" not in ds.scenes and "bull" in caplog.text
    ds = open_dataset("middlebury2001", root, allow_jpeg=True)
    assert "bull" in ds.scenes and ds["bull"].meta["lossy"] is True


def test_eth3d_calibration_and_invalid():
    root = need("eth3d_two_view_training")
    f = open_dataset("eth3d", root)[0]
    assert f.calib.f == pytest.approx(542.019) and f.calib.baseline == pytest.approx(0.0595549)
    assert f.calib.cx == pytest.approx(541.836) and f.calib.cy == pytest.approx(255.198)
    raw = read_pfm(root / "playground_1l" / "disp0.pfm")
    np.testing.assert_array_equal(np.isnan(f.gt_disparity), ~np.isfinite(raw))
    assert 0.4 < np.isfinite(f.gt_disparity).mean() < 0.6


def test_kitti2012_calibration_and_masks():
    root = need("kitti2012_training")
    ds = open_dataset("kitti2012", root)
    f = ds[0]
    assert f.calib.f == pytest.approx(718.856)
    assert f.calib.baseline == pytest.approx(386.1448 / 718.856, rel=1e-6)
    assert f.calib.cx == pytest.approx(607.1928) and f.calib.cy == pytest.approx(185.2157)
    assert 0.2 < np.isfinite(f.gt_disparity).mean() < 0.4
    assert f.nocc_mask.sum() <= np.isfinite(f.gt_disparity).sum()
    assert f.sensor_depth is None  # no velodyne scan in this sample
    fc = open_dataset("kitti2012", root, color=True)[0]
    assert fc.left.ndim == 3 and fc.calib.baseline == pytest.approx((45.38225 + 337.2877) / 718.856, rel=1e-5)
    noc = open_dataset("kitti2012", root, gt="noc")[0]
    np.testing.assert_array_equal(np.isfinite(noc.gt_disparity), f.nocc_mask)


# ---------------------------------------------------------------- written layouts

MIDD2014_CALIB = """cam0=[ 3979.911 0 1244.772;0 3979.911 1019.507; 0 0 1]
cam1 = [3979.911 0 1369.115; 0 3979.911 1019.507; 0 0 1]
doffs=124.343
baseline=193.001\r
width=2964
height=2000
ndisp=270
isint=0
vmin=23
vmax=245
"""


@pytest.fixture
def midd2014_root(tmp_path):
    rng = np.random.default_rng(1)
    scene = tmp_path / "Toy-perfect"
    scene.mkdir()
    left = rng.integers(0, 256, (20, 30, 3), dtype=np.uint8)
    cv2.imwrite(str(scene / "im0.png"), left)
    cv2.imwrite(str(scene / "im1.png"), left[:, ::-1].copy())
    gt = rng.uniform(1, 10, (20, 30)).astype(np.float32)
    gt[0, :5] = np.inf
    write_pfm(scene / "disp0GT.pfm", gt)
    mask = np.full((20, 30), 255, np.uint8)
    mask[5, 5] = 128
    cv2.imwrite(str(scene / "mask0nocc.png"), mask)
    (scene / "calib.txt").write_text(MIDD2014_CALIB)
    return tmp_path, left, gt


def test_middlebury2014_reader(midd2014_root):
    root, left, gt = midd2014_root
    ds = open_dataset("auto", root)
    assert ds.name == "middlebury2014" and ds.scenes == ["Toy-perfect"] and ds.max_disparity == 270
    f = ds[0]
    np.testing.assert_array_equal(f.left, left[..., ::-1])  # written BGR by OpenCV, read back RGB
    assert np.isnan(f.gt_disparity[0, :5]).all()
    np.testing.assert_array_equal(f.gt_disparity[1:], gt[1:])
    assert not f.nocc_mask[5, 5] and not f.nocc_mask[0, 0] and f.nocc_mask[1, 1]
    assert f.calib.f == pytest.approx(3979.911) and f.calib.baseline == pytest.approx(0.193001)
    assert f.calib.doffs == pytest.approx(124.343) and f.calib.cx == pytest.approx(1244.772)
    # the same scene opened as its own root
    assert open_dataset("auto", root / "Toy-perfect").scenes == ["Toy-perfect"]


def test_middlebury_calib_parser_tolerates_whitespace(tmp_path):
    (tmp_path / "calib.txt").write_text(MIDD2014_CALIB)
    c = parse_middlebury_calib(tmp_path / "calib.txt")
    assert c["cam1"][0, 2] == pytest.approx(1369.115) and c["baseline"] == pytest.approx(193.001)
    (tmp_path / "bad.txt").write_text("cam0=[1 2 3]\n")
    with pytest.raises(ValueError, match="cam0"):
        parse_middlebury_calib(tmp_path / "bad.txt")


@pytest.fixture
def folder_root(tmp_path):
    rng = np.random.default_rng(2)
    for sub in ("left", "right", "disp"):
        (tmp_path / sub).mkdir()
    for i in range(3):
        img = rng.integers(0, 256, (12, 16), dtype=np.uint8)
        cv2.imwrite(str(tmp_path / "left" / f"{i:03d}.png"), img)
        cv2.imwrite(str(tmp_path / "right" / f"{i:03d}.png"), img)
        d = np.full((12, 16), 3 * 256, np.uint16)
        d[0, 0] = 0
        cv2.imwrite(str(tmp_path / "disp" / f"{i:03d}.png"), d)
    (tmp_path / "calib.json").write_text('{"f": 100.0, "baseline": 0.2}')
    return tmp_path


def test_folder_reader(folder_root):
    ds = open_dataset("auto", folder_root)
    assert ds.name == "folder" and ds.scenes == ["000", "001", "002"] and len(ds) == 3
    assert ds.has_ground_truth and not ds.has_sparse_input and ds[0].sparse_disparity is None
    f = ds[-1]
    assert f.name == "002" and f.left.shape == (12, 16) and f.calib.f == 100.0
    assert np.isnan(f.gt_disparity[0, 0]) and np.nanmax(f.gt_disparity) == 3.0
    assert [fr.name for fr in ds] == ds.scenes
    assert open_dataset("folder", folder_root, disp_scale=1.0)[0].gt_disparity[1, 1] == 768.0


def test_folder_reader_own_sparse_input(tmp_path):
    """``sparse/`` gives every frame its own points (no ground truth needed); a missing file fails that frame only."""
    frame = own_scene(0.25)
    maps = write_own_folder(tmp_path, frame)
    ds = open_dataset("auto", tmp_path)
    assert ds.name == "folder" and ds.has_sparse_input and not ds.has_ground_truth
    for i, fr in enumerate(ds):
        assert fr.gt_disparity is None and fr.meta["lidar_like"] is False
        np.testing.assert_allclose(fr.sparse_disparity, maps[i], atol=1e-6)  # NaN where no point, on both
    (tmp_path / "sparse" / "001.npy").unlink()
    ds = open_dataset("folder", tmp_path)
    with pytest.raises(FileNotFoundError, match=r"no sparse input for frame '001'"):
        ds[1]
    assert ds[2].sparse_disparity is not None
    assert open_dataset("folder", tmp_path).select(["002"])[0].name == "002"


def test_folder_reader_sparse_folder_errors(tmp_path):
    write_own_folder(tmp_path, own_scene(0.125), forms=("png", "png"))
    (tmp_path / "sparse" / "007.png").write_bytes(b"")
    with pytest.raises(ValueError, match="007 matches no left image"):
        open_dataset("folder", tmp_path)
    (tmp_path / "sparse" / "007.png").unlink()
    np.save(tmp_path / "sparse" / "000.npy", np.zeros((2, 2)))
    with pytest.raises(ValueError, match="two sparse inputs for frame '000'"):
        open_dataset("folder", tmp_path)
    for p in (tmp_path / "sparse").iterdir():
        p.unlink()
    with pytest.raises(ValueError, match="holds no"):
        open_dataset("folder", tmp_path)


def test_folder_reader_mismatch(folder_root):
    (folder_root / "right" / "002.png").unlink()
    with pytest.raises(ValueError, match="3 left images but 2 right"):
        open_dataset("folder", folder_root)


def test_select_limit_and_indexing(folder_root):
    ds = open_dataset("folder", folder_root).select(["002", "000"])
    assert ds.scenes == ["002", "000"] and ds[0].name == "002"
    assert open_dataset("folder", folder_root).select(limit=1).scenes == ["000"]
    with pytest.raises(ValueError, match="scenes"):
        open_dataset("folder", folder_root).select(["nope"])
    with pytest.raises(IndexError):
        ds[5]
    with pytest.raises(KeyError):
        ds["nope"]
    with pytest.raises(TypeError):
        ds[1.5]


def test_open_dataset_errors(tmp_path):
    with pytest.raises(ValueError, match="looked for") as exc:
        open_dataset("auto", tmp_path)
    for name in DATASETS.names():
        assert name in str(exc.value)
    with pytest.raises(FileNotFoundError, match="root"):
        open_dataset("auto", tmp_path / "missing")
    with pytest.raises(ValueError, match="unknown dataset"):
        open_dataset("nope", tmp_path)
    with pytest.raises(ValueError, match="no middlebury2006 scene"):
        open_dataset("middlebury2006", tmp_path)
    with pytest.raises(TypeError, match="root"):
        open_dataset("auto", 3)


def test_auto_order_tries_every_reader_once_specific_first():
    assert sorted(AUTO_ORDER) == DATASETS.names()
    assert len(set(AUTO_ORDER)) == len(AUTO_ORDER)
    assert AUTO_ORDER[-1] == "folder"
    # ETH3D is the Middlebury-2014 layout without vmin: it must be tried before its parent.
    assert AUTO_ORDER.index("eth3d") < AUTO_ORDER.index("middlebury2014")


def test_reader_class_returns_dataset_classes_and_rejects_other_factories(monkeypatch):
    for name in DATASETS.names():
        cls = reader_class(name)
        assert issubclass(cls, Dataset) and cls.name == name
    monkeypatch.setitem(DATASETS._items, "not-a-reader", lambda root: root)
    with pytest.raises(TypeError, match="not-a-reader"):
        reader_class("not-a-reader")
    with pytest.raises(ValueError, match="unknown dataset"):
        reader_class("nope")


def test_reader_option_validation():
    root = need("middlebury2005_2006_thirdsize")
    with pytest.raises(ValueError, match="scale"):
        open_dataset("middlebury2006", root, scale=0)
    with pytest.raises(ValueError, match="lr_tol"):
        open_dataset("middlebury2006", root, lr_tol=-1)
    with pytest.raises(ValueError, match="gt"):
        open_dataset("kitti2012", need("kitti2012_training"), gt="both")


# ---------------------------------------------------------------- nocc, velodyne, kitti layout


def test_lr_consistency_mask_matches_reference():
    rng = np.random.default_rng(3)
    dl = rng.uniform(0, 6, (9, 20)).round().astype(np.float32)
    dr = dl.copy()
    dr[rng.random(dr.shape) < 0.3] += 3
    dl[0, 3] = np.nan
    got = lr_consistency_mask(dl, dr, tol=1.0)
    ref = np.zeros_like(got)
    for y in range(9):
        for x in range(20):
            d = dl[y, x]
            if np.isnan(d):
                continue
            xr = int(np.rint(x - d))
            ref[y, x] = 0 <= xr < 20 and abs(dr[y, xr] - d) <= 1.0
    np.testing.assert_array_equal(got, ref)
    with pytest.raises(ValueError, match="disp_right"):
        lr_consistency_mask(dl, dr[:, :5])


def test_project_points_matches_reference():
    rng = np.random.default_rng(4)
    pts = np.column_stack([rng.uniform(-3, 3, 300), rng.uniform(-2, 2, 300), rng.uniform(-1, 10, 300)])
    p = np.array([[50.0, 0, 16, 0], [0, 50.0, 12, 0], [0, 0, 1, 0]])
    got = project_points(pts, p, (24, 32))
    ref = np.zeros((24, 32), np.float32)
    for x, y, z in pts:
        if z <= 0:
            continue
        u, v = int(np.floor(50 * x / z + 16 + 0.5)), int(np.floor(50 * y / z + 12 + 0.5))
        if 0 <= u < 32 and 0 <= v < 24 and (ref[v, u] == 0 or z < ref[v, u]):
            ref[v, u] = z
    np.testing.assert_allclose(got, ref, rtol=1e-6)
    with pytest.raises(ValueError, match="points_cam"):
        project_points(pts[:, :2], p, (24, 32))


def test_kitti_layout_with_velodyne(tmp_path):
    """A KITTI-style folder with a scan: points land where P0 projects them, with their depth."""
    for sub in ("image_0", "image_1", "disp_occ", "disp_noc", "calib", "velodyne"):
        (tmp_path / sub).mkdir()
    img = np.random.default_rng(5).integers(0, 256, (40, 60), dtype=np.uint8)
    for sub in ("image_0", "image_1"):
        cv2.imwrite(str(tmp_path / sub / "000001_10.png"), img)
    disp = np.zeros((40, 60), np.uint16)
    disp[10:20, 10:20] = 5 * 256
    cv2.imwrite(str(tmp_path / "disp_occ" / "000001_10.png"), disp)
    cv2.imwrite(str(tmp_path / "disp_noc" / "000001_10.png"), disp)
    p0 = "50 0 30 0 0 50 20 0 0 0 1 0"
    p1 = "50 0 30 -25 0 50 20 0 0 0 1 0"
    # velodyne: x forward, y left, z up -> camera: x = -y, y = -z, z = x
    tr = "0 -1 0 0 0 0 -1 0 1 0 0 0"
    (tmp_path / "calib" / "000001.txt").write_text(
        f"P0: {p0}\nP1: {p1}\nP2: {p0}\nP3: {p1}\nR0_rect: 1 0 0 0 1 0 0 0 1\nTr_velo_to_cam: {tr}\n"
    )
    scan = np.array([[10.0, 0.0, 0.0, 1], [5.0, -1.0, 0.5, 1], [-5.0, 0, 0, 1]], np.float32)
    scan.tofile(tmp_path / "velodyne" / "000001.bin")
    ds = open_dataset("auto", tmp_path)
    assert ds.name == "kitti2012" and ds.scenes == ["000001_10"]
    f = ds[0]
    assert f.calib.baseline == pytest.approx(0.5)
    assert f.sensor_depth[20, 30] == pytest.approx(10.0)  # straight ahead
    assert f.sensor_depth[15, 40] == pytest.approx(5.0)  # u = 30 + 50*1/5, v = 20 - 50*0.5/5
    assert (f.sensor_depth > 0).sum() == 2  # the point behind is dropped
    assert f.sparse_disparity[20, 30] == pytest.approx(50 * 0.5 / 10.0)
    np.testing.assert_allclose(read_velodyne_bin(tmp_path / "velodyne" / "000001.bin"), scan)
    cam = velo_to_camera(scan, parse_kitti_calib(tmp_path / "calib" / "000001.txt")["Tr_velo_to_cam"])
    np.testing.assert_allclose(cam[0], [0, 0, 10])
