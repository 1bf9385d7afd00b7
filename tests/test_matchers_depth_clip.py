"""The valid depth range of every output (``[depth_clip]``): defaults from the matcher's range and the rig."""

from __future__ import annotations

import math

import numpy as np
import pytest

from helpers.points import read_ply
from helpers.toml import toml_dumps
from vpp_service.frame import Calibration
from vpp_service.matchers import build_matcher
from vpp_service.matchers.depth_clip import DepthClip
from vpp_service.service.app import run_service
from vpp_service.service.config import load_config, validate_config
from vpp_service.settings import SettingsError
from vpp_service.sinks.files import decode_png16, encode_png16

KITTI = Calibration(f=721.5377, baseline=0.5372)  # f * B = 387.6 m px
MIDDLEBURY = Calibration(f=3979.911, baseline=0.193001, doffs=124.343)  # Motorcycle, full size


@pytest.mark.parametrize(
    ("options", "calib", "bounds"),
    [
        ({"max_disparity": 64}, KITTI, (1.0, 64.0)),  # 1 px .. the top of the range
        ({"max_disparity": 64, "min_disparity": 4}, KITTI, (4.0, 68.0)),  # OpenCV's range starts at min_disparity
        ({"max_disparity": 128}, MIDDLEBURY, (1.0, 128.0)),
        ({"max_disparity": 128}, None, (1.0, 128.0)),
    ],
)
def test_default_bounds_come_from_the_matcher_range_and_the_rig(options, calib, bounds):
    matcher = build_matcher("sgbm", options)
    assert DepthClip().disparity_bounds(matcher, calib) == bounds
    if calib is not None:
        fb, doffs = calib.f * calib.baseline, calib.doffs
        near, far = DepthClip().depth_bounds(matcher, calib)
        assert near == pytest.approx(fb / (bounds[1] + doffs)) and far == pytest.approx(fb / (bounds[0] + doffs))


def test_the_kitti_default_is_hundreds_of_metres_not_kilometres():
    near, far = DepthClip().depth_bounds(build_matcher("sgbm", {"max_disparity": 128}), KITTI)
    assert 380 < far < 395 and 3.0 < near < 3.1
    assert KITTI.f * KITTI.baseline / (1 / 16) > 6000  # what SGBM's smallest step would have claimed


def test_metric_bounds_replace_the_defaults_on_calibrated_frames():
    matcher = build_matcher("sgbm", {"max_disparity": 128})
    clip = DepthClip(min_depth_m=5.0, max_depth_m=100.0)
    fb = KITTI.f * KITTI.baseline
    assert clip.disparity_bounds(matcher, KITTI) == pytest.approx((fb / 100.0, fb / 5.0))
    assert clip.depth_bounds(matcher, KITTI) == pytest.approx((5.0, 100.0))
    assert clip.disparity_bounds(matcher, None) == (1.0, 128.0)  # no calibration: no metric meaning


def test_apply_invalidates_everything_outside_the_range_and_nothing_inside():
    matcher = build_matcher("sgbm", {"max_disparity": 128})
    d = np.array([[1 / 16, 0.5, 1.0, 3.0, 30.0, 64.0], [128.0, 128.5, 0.0, -3.0, np.nan, np.inf]], np.float32)
    out = DepthClip().apply(d.copy(), matcher, KITTI)
    valid = [[False, False, True, True, True, True], [True, False, False, False, False, False]]
    np.testing.assert_array_equal(np.isfinite(out), valid)
    np.testing.assert_array_equal(out[np.isfinite(out)], d[np.array(valid)])  # kept values untouched
    fb = KITTI.f * KITTI.baseline
    far = DepthClip(max_depth_m=100.0).apply(d.copy(), matcher, KITTI)  # d_lo = 3.88 px
    assert np.all(fb / far[np.isfinite(far)] <= 100.0)
    np.testing.assert_array_equal(np.isfinite(far)[0], [False, False, False, False, True, True])


def test_apply_keeps_a_positive_depth_with_a_large_doffs():
    """Middlebury: a far max_depth_m gives d_lo < 0; d <= 0 stays invalid (PNG's 0), small d > 0 are depths."""
    matcher = build_matcher("sgbm", {"max_disparity": 128})
    clip = DepthClip(max_depth_m=1000.0)
    assert clip.disparity_bounds(matcher, MIDDLEBURY)[0] < 0
    out = clip.apply(np.array([[-1.0, 0.0, 0.25, 2.0]], np.float32), matcher, MIDDLEBURY)
    np.testing.assert_array_equal(np.isfinite(out), [[False, False, True, True]])


def test_apply_copies_a_read_only_map():
    matcher = build_matcher("sgbm", {"max_disparity": 16})
    d = np.array([[0.5, 8.0]], np.float32)
    d.flags.writeable = False
    out = DepthClip().apply(d, matcher, None)
    assert out is not d and d[0, 0] == 0.5 and math.isnan(out[0, 0])


def test_npy_and_png_agree_on_invalid_pixels_after_the_clip():
    """Without the clip a 0 px disparity is valid in .npy and invalid (0) in the PNG; with it both say invalid."""
    rng = np.random.default_rng(3)
    d = rng.uniform(-2.0, 70.0, (40, 60)).astype(np.float32)
    d[rng.random(d.shape) < 0.1] = 0.0  # SGBM's min_disparity 0 is a valid output
    d[rng.random(d.shape) < 0.05] = np.nan
    assert np.any(np.isfinite(d) & np.isnan(decode_png16(encode_png16(d))))  # they disagree unclipped
    out = DepthClip().apply(d, build_matcher("sgbm", {"max_disparity": 64}), KITTI)
    np.testing.assert_array_equal(np.isnan(decode_png16(encode_png16(out))), np.isnan(out))


@pytest.mark.parametrize(
    ("section", "match"),
    [
        ({"max_depth_m": -1.0}, r"depth_clip\.max_depth_m: got -1\.0; expected >= 0"),
        ({"min_depth_m": float("nan")}, "min_depth_m"),
        (
            {"min_depth_m": 10.0, "max_depth_m": 5.0},
            r"depth_clip\.max_depth_m: got 5\.0; expected > min_depth_m \(10\.0\)",
        ),
        ({"max_depth": 5.0}, r"depth_clip\.max_depth"),
    ],
)
def test_config_errors_name_the_key(section, match):
    with pytest.raises(SettingsError, match=match):
        load_config(None, {"depth_clip": section})


def test_config_round_trips():
    cfg = load_config(None, {"depth_clip": {"min_depth_m": 0.5, "max_depth_m": 40.0}})
    assert cfg.depth_clip == DepthClip(0.5, 40.0)
    assert validate_config(cfg.to_dict()).depth_clip == cfg.depth_clip


def test_every_file_output_of_the_service_agrees_on_the_clip(tmp_path):
    """A service run: .npy disparity, 16-bit PNG, depth .npy and .ply agree on the valid pixels, inside the range."""
    f, b = 500.0, 0.1  # the synthetic scene's calibration
    near, far = f * b / 40.0, f * b / 20.0  # disparities 20 .. 40 px
    data = {
        "service": {"out": str(tmp_path / "out"), "summary": False},
        "zenoh": {"enabled": False},
        "source": {
            "type": "sim",
            "scene": "synthetic",
            "scene_options": {"height": 64, "width": 128, "max_disparity": 48, "f": f, "baseline": b},
            "sensor": "none",
            "count": 2,
        },
        "vpp": {"enabled": False},
        "matcher": {"name": "sgbm", "max_disparity": 64},
        "depth_clip": {"min_depth_m": near, "max_depth_m": far},
        "sinks": [
            {
                "type": "files",
                "dir": "{out}/frames",
                "create_dir": True,
                "formats": ["png16", "npy"],
                "depth": True,
                "points": True,
                "points_stride": 1,
            }
        ],
    }
    (tmp_path / "run.toml").write_text(toml_dumps(data))
    summary = run_service(validate_config(data), stream=None)
    assert summary["counters"]["processed"] == 2
    frames = tmp_path / "out" / "frames"
    for seq in range(2):
        disp = np.load(frames / f"rig0_{seq:06d}_disparity.npy")
        png = decode_png16((frames / f"rig0_{seq:06d}_disparity.png").read_bytes())
        depth = np.load(frames / f"rig0_{seq:06d}_depth.npy")
        ok = np.isfinite(disp)
        assert 0.2 < ok.mean() < 0.95  # the scene spans more than 20..40 px: some pixels were clipped
        np.testing.assert_array_equal(np.isnan(png), ~ok)
        np.testing.assert_array_equal(np.isnan(depth), ~ok)
        assert disp[ok].min() >= 20.0 and disp[ok].max() <= 40.0
        assert depth[ok].min() >= near * (1 - 1e-6) and depth[ok].max() <= far * (1 + 1e-6)
        _, cloud = read_ply((frames / f"rig0_{seq:06d}_points.ply").read_bytes())  # one point per valid pixel
        assert len(cloud) == ok.sum() and np.array_equal(np.sort(cloud["z"]), np.sort(depth[ok]))
        assert cloud["z"].max() <= far * (1 + 1e-6) and cloud["z"].min() >= near * (1 - 1e-6)
