"""Sparse depth-sensor simulators: density, beam structure, noise statistics, seeds, ranges."""

from __future__ import annotations

import numpy as np
import pytest

from vpp_service.frame import Calibration, StereoFrame
from vpp_service.settings import SettingsError
from vpp_service.sources.sensors import SENSORS, LidarSensor, build_sensor


@pytest.fixture(scope="module")
def frame():
    """A 200 x 300 calibrated frame, slanted-plane GT (valid everywhere but a hole)."""
    h, w = 200, 300
    ys, xs = np.mgrid[0:h, 0:w]
    gt = (10 + 30 * ys / h + 5 * xs / w).astype(np.float32)
    gt[50:80, 200:260] = np.nan
    img = np.zeros((h, w, 3), np.uint8)
    return StereoFrame(
        left=img,
        right=img,
        gt_disparity=gt,
        calib=Calibration(f=400.0, baseline=0.2, doffs=2.0, cx=150.0, cy=100.0),
        name="plane",
    )


def depth_of(frame, d):
    c = frame.calib
    return c.f * c.baseline / (d + c.doffs)


@pytest.mark.parametrize("name", ["uniform", "lidar", "tof"])
def test_smoke_points_are_ground_truth(frame, name):
    out = build_sensor(name, {}).simulate(frame, seed=0)
    sp = out.sparse_disparity
    assert sp.dtype == np.float32 and sp.shape == frame.shape
    have = np.isfinite(sp)
    assert have.sum() > 100
    np.testing.assert_allclose(sp[have], frame.gt_disparity[have], rtol=1e-5)
    # metric depth where calibrated, 0 elsewhere, consistent with Z = f b / (d + doffs)
    np.testing.assert_array_equal(out.sensor_depth > 0, have)
    np.testing.assert_allclose(out.sensor_depth[have], depth_of(frame, sp[have]), rtol=1e-4)
    assert frame.sparse_disparity is None  # input untouched
    assert out.meta["sensor"] == name


@pytest.mark.parametrize("name", ["uniform", "lidar", "tof"])
def test_seeds_reproducible(frame, name):
    opts = {
        "uniform": {"noise_px": 0.5},
        "lidar": {"noise_m": 0.05, "dropout": 0.3},
        "tof": {"noise_k": 0.01, "dropout": 0.3},
    }[name]
    s = build_sensor(name, opts)
    a, b, c = (s.simulate(frame, seed=k).sparse_disparity for k in (7, 7, 8))
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(np.nan_to_num(a), np.nan_to_num(c))


@pytest.mark.parametrize("density", [0.01, 0.05, 0.2])
def test_uniform_density(frame, density):
    sp = build_sensor("uniform", {"density": density}).simulate(frame, 1).sparse_disparity
    n_valid = np.isfinite(frame.gt_disparity).sum()
    assert np.isfinite(sp).sum() == pytest.approx(density * n_valid, abs=1)
    assert not np.isfinite(sp[50:80, 200:260]).any()


def test_uniform_noise_statistics(frame):
    sp = build_sensor("uniform", {"density": 0.3, "noise_px": 0.7}).simulate(frame, 2).sparse_disparity
    err = (sp - frame.gt_disparity)[np.isfinite(sp)]
    assert abs(err.mean()) < 0.03 and err.std() == pytest.approx(0.7, rel=0.05)


def test_lidar_beams_make_row_bands(frame):
    opts = {"beams": 32, "fov_up": 10.0, "fov_down": -20.0}
    sensor = build_sensor("lidar", opts)
    sp = sensor.simulate(frame, 0).sparse_disparity
    # expected visible beams from the geometry: v = cy - f tan(el), inside [0, H)
    el = np.deg2rad(np.linspace(10.0, -20.0, 32))
    v = 100.0 - 400.0 * np.tan(el)
    expected = np.unique(np.floor(v[(v >= -0.5) & (v < 199.5)] + 0.5))
    centre_rows = np.unique(np.nonzero(np.isfinite(sp[:, 145:156]))[0])
    np.testing.assert_array_equal(centre_rows, expected)
    # beams curve away from the centre but stay thin bands: every hit is near a beam row
    rows = np.nonzero(np.isfinite(sp))[0]
    assert np.min(np.abs(rows[:, None] - expected[None, :]), axis=1).max() <= 12
    # azimuth step 0.2 deg at f = 400 px: about one sample per 1.4 px along a beam
    mid = int(expected[np.argmin(np.abs(expected - 100))])
    assert np.isfinite(sp[mid - 1 : mid + 2]).sum() > 150


def test_lidar_range_limits_and_noise(frame):
    base = LidarSensor(LidarSensor.Options(beams=128, fov_up=15.0, fov_down=-15.0, azimuth_step=0.1))
    ref = base.simulate(frame, 0)
    have = ref.sensor_depth > 0
    zmin, zmax = ref.sensor_depth[have].min(), ref.sensor_depth[have].max()
    limited = build_sensor(
        "lidar",
        {"beams": 128, "fov_up": 15.0, "fov_down": -15.0, "azimuth_step": 0.1, "max_range": float((zmin + zmax) / 2)},
    ).simulate(frame, 0)
    h, w = frame.shape
    ys, xs = np.mgrid[0:h, 0:w]
    ray = np.sqrt(1 + ((xs - 150) / 400.0) ** 2 + ((ys - 100) / 400.0) ** 2)
    lim = limited.sensor_depth > 0
    assert 0 < lim.sum() < have.sum()
    assert (limited.sensor_depth[lim] * ray[lim]).max() <= (zmin + zmax) / 2 + 1e-4
    noisy = build_sensor(
        "lidar", {"beams": 128, "fov_up": 15.0, "fov_down": -15.0, "azimuth_step": 0.1, "noise_m": 0.05}
    ).simulate(frame, 3)
    m = noisy.sensor_depth > 0
    true_z = depth_of(frame, frame.gt_disparity[m])
    range_err = (noisy.sensor_depth[m] - true_z) * ray[m]
    assert range_err.std() == pytest.approx(0.05, rel=0.08) and abs(range_err.mean()) < 0.005


def test_lidar_dropout(frame):
    full = np.isfinite(build_sensor("lidar", {}).simulate(frame, 0).sparse_disparity).sum()
    half = np.isfinite(build_sensor("lidar", {"dropout": 0.5}).simulate(frame, 0).sparse_disparity).sum()
    assert half / full == pytest.approx(0.5, abs=0.06)


def test_tof_grid_noise_and_range(frame):
    out = build_sensor("tof", {"grid_w": 30, "grid_h": 20}).simulate(frame, 0)
    rows, cols = np.nonzero(np.isfinite(out.sparse_disparity))
    assert np.unique(rows).size == 20 and np.unique(cols).size == 30
    noisy = build_sensor("tof", {"grid_w": 150, "grid_h": 100, "noise_k": 0.02}).simulate(frame, 1)
    m = noisy.sensor_depth > 0
    z = depth_of(frame, frame.gt_disparity[m])
    norm = (noisy.sensor_depth[m] - z) / (0.02 * z**2)
    assert norm.std() == pytest.approx(1.0, rel=0.06)
    limited = build_sensor("tof", {"max_range": 4.0}).simulate(frame, 0)
    assert limited.sensor_depth.max() <= 4.0 and (limited.sensor_depth > 0).any()


def test_uncalibrated_frame_uses_nominal(frame):
    bare = frame.with_(calib=None)
    out = build_sensor("lidar", {"nominal_f": 400.0}).simulate(bare, 0)
    assert out.sensor_depth is None and np.isfinite(out.sparse_disparity).sum() > 100
    # nominal f, baseline 0.1 -> depth 40 / d; max_range below every depth -> nothing
    none = build_sensor("tof", {"nominal_f": 400.0, "max_range": 0.5}).simulate(bare, 0)
    assert not np.isfinite(none.sparse_disparity).any()


def test_errors(frame):
    assert SENSORS.names() == ["lidar", "tof", "uniform"]
    with pytest.raises(ValueError, match="unknown sensor"):
        build_sensor("radar", {})
    with pytest.raises(SettingsError, match=r"^sensor\.uniform\.density: got 1\.5; expected in \(0, 1\]$"):
        build_sensor("uniform", {"density": 1.5})
    with pytest.raises(SettingsError, match=r"sensor\.lidar\.beam"):
        build_sensor("lidar", {"beam": 3})
    with pytest.raises(SettingsError, match="max_range"):
        build_sensor("tof", {"max_range": 0.05})
    with pytest.raises(SettingsError, match="dropout"):
        build_sensor("lidar", {"dropout": 1.0})
    with pytest.raises(ValueError, match="gt_disparity"):
        build_sensor("uniform").simulate(frame.with_(gt_disparity=None), 0)
    with pytest.raises(ValueError, match="seed"):
        build_sensor("uniform").simulate(frame, -1)
    with pytest.raises(TypeError, match="frame"):
        build_sensor("uniform").simulate("frame", 0)


# ---------------------------------------------------------------- a LiDAR beside the camera: see-through points
F, B, CX, CY, H2, W2 = 400.0, 0.2, 119.3, 59.6, 120, 240
Z_FG, Z_BG, T_X = 2.0, 8.0, 0.1  # foreground / background depth (m); the LiDAR 0.1 m right of the camera
TWO_PLANE_OPTS = {"beams": 16, "fov_up": 8.0, "fov_down": -8.0, "azimuth_step": 0.5, "pose": [T_X, 0.0, 0.0]}


def beam_columns_rows():
    """Where the beams cross the LiDAR's image plane (the simulator's beam model, module docs)."""
    az = np.deg2rad(np.arange(-40, 41) * 0.5)
    el = np.deg2rad(np.linspace(8.0, -8.0, 16))
    u = CX + F * np.tan(az)[None, :]
    v = CY - F * np.tan(el)[:, None] / np.cos(az)[None, :]
    u, v = np.broadcast_arrays(u, v)
    return u.ravel(), v.ravel()


def two_plane_frame(edge):
    """Foreground plane at Z_FG over columns [0, edge), background plane at Z_BG elsewhere (fronto-parallel)."""
    gt = np.full((H2, W2), F * B / Z_BG, np.float32)
    gt[:, :edge] = F * B / Z_FG
    img = np.zeros((H2, W2), np.uint8)
    return StereoFrame(left=img, right=img, gt_disparity=gt, calib=Calibration(f=F, baseline=B, cx=CX, cy=CY))


def hand_scan(edge):
    """Analytic ray casting of the beams, projected into the camera (nearest wins a pixel).

    Each beam from the LiDAR hits the foreground plane if its hit lies on the visible foreground (camera
    column < edge - 0.5), else the background plane.
    """
    u, v = beam_columns_rows()
    col, row = np.floor(u + 0.5), np.floor(v + 0.5)
    inside = (col >= 0) & (col < W2) & (row >= 0) & (row < H2)
    u, v = u[inside], v[inside]
    dx, dy = (u - CX) / F, (v - CY) / F  # beam direction (z = 1) in the LiDAR frame = camera axes
    best = {}
    for x_dir, y_dir in zip(dx, dy, strict=True):
        z = Z_FG
        u_fg = CX + F * (T_X + Z_FG * x_dir) / Z_FG
        if not -0.5 <= u_fg < edge - 0.5:
            z = Z_BG  # past the foreground's silhouette: the background
        x, y = T_X + z * x_dir, z * y_dir
        c, r = int(np.floor(CX + F * x / z + 0.5)), int(np.floor(CY + F * y / z + 0.5))
        if 0 <= c < W2 and 0 <= r < H2 and ((r, c) not in best or z < best[r, c]):
            best[r, c] = z
    return best


def clear_edge(t_x=T_X):
    """An edge column with no beam within 1.5 px of the foreground's silhouette as the LiDAR sees it.

    The simulator's z-buffer resolves a silhouette to a pixel; the hand computation is exact.
    """
    u, _ = beam_columns_rows()
    shift = F * t_x / Z_FG
    for edge in range(100, 160):
        if np.min(np.abs(u - (edge - 0.5 - shift))) > 1.5:
            return edge
    raise AssertionError("no clear edge")


def test_offset_lidar_two_planes_see_through_matches_hand_computation():
    edge = clear_edge()
    frame = two_plane_frame(edge)
    out = build_sensor("lidar", TWO_PLANE_OPTS).simulate(frame, 0)
    sp = out.sparse_disparity
    best = hand_scan(edge)
    want = np.full((H2, W2), np.nan, np.float32)
    for (r, c), z in best.items():
        want[r, c] = F * B / z
    np.testing.assert_array_equal(np.isfinite(sp), np.isfinite(want))
    np.testing.assert_allclose(sp[np.isfinite(sp)], want[np.isfinite(want)], rtol=1e-5)
    # see-through: background depth on a foreground pixel; the band is f t (1/Z_fg - 1/Z_bg) = 15 px wide
    see_through = np.isfinite(sp) & (np.abs(sp - frame.gt_disparity) > 1)
    hand = sum(1 for (r, c), z in best.items() if z == Z_BG and c < edge)
    assert see_through.sum() == hand > 0
    cols = np.nonzero(see_through)[1]
    band = F * T_X * (1 / Z_FG - 1 / Z_BG)
    assert cols.min() >= edge - band - 1 and cols.max() < edge
    assert out.meta["lidar_like"] is True


def test_offset_lidar_on_the_other_side_sees_no_hidden_background():
    # the LiDAR left of the camera sees less around this edge: background it cannot see is hidden by the
    # foreground in its z-buffer, and nothing lands on a foreground pixel with background depth
    frame = two_plane_frame(clear_edge(-T_X))
    out = build_sensor("lidar", {**TWO_PLANE_OPTS, "pose": [-T_X, 0.0, 0.0]}).simulate(frame, 0)
    sp = out.sparse_disparity
    assert np.isfinite(sp).sum() > 300
    assert not np.any(np.abs(sp[np.isfinite(sp)] - frame.gt_disparity[np.isfinite(sp)]) > 1e-3)


def test_zero_pose_zbuffer_path_matches_ground_truth(frame):
    # the rendered path at the camera centre: every return lies on the ground truth of its pixel
    out = build_sensor("lidar", {"zbuffer": True}).simulate(frame, 0)
    sp, gt = out.sparse_disparity, frame.gt_disparity
    have = np.isfinite(sp) & np.isfinite(gt)
    assert have.sum() > 100
    np.testing.assert_allclose(sp[have], gt[have], rtol=1e-3, atol=0.05)


def test_pose_presets_and_rotation():
    s = build_sensor("lidar", {"pose": "kitti"})
    assert isinstance(s, LidarSensor) and s.offset
    np.testing.assert_allclose(s.translation(), [-0.0028, -0.0751, -0.2721])
    assert not build_sensor("lidar", {}).offset
    r = build_sensor("lidar", {"rotation": [0.0, 90.0, 0.0]})
    assert isinstance(r, LidarSensor) and r.offset
    np.testing.assert_allclose(r.rotation() @ [0.0, 0.0, 1.0], [1.0, 0.0, 0.0], atol=1e-12)


@pytest.mark.parametrize(
    ("opts", "match"),
    [
        ({"pose": "velodyne"}, r"sensor\.lidar\.pose: got 'velodyne'; expected one of 'kitti', 'zero'"),
        ({"pose": [0.0, 1.0]}, "pose"),
        ({"pose": [0.0, float("nan"), 0.0]}, "pose"),
        ({"rotation": [0.0, 0.0, 400.0]}, r"rotation\[2\]: got 400\.0; expected in \[-180, 180\]"),
    ],
)
def test_pose_errors(opts, match):
    with pytest.raises(ValueError, match=match):
        build_sensor("lidar", opts)


def test_only_an_offset_lidar_is_lidar_like(frame):
    for name in ("uniform", "tof", "lidar"):  # the lidar at the camera centre cannot see past an edge
        assert build_sensor(name, {}).simulate(frame, 0).meta["lidar_like"] is False
    assert build_sensor("lidar", {"zbuffer": True}).simulate(frame, 0).meta["lidar_like"] is False
    assert build_sensor("lidar", {"pose": "kitti"}).simulate(frame, 0).meta["lidar_like"] is True
