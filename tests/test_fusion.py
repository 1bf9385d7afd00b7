"""The fusion step (``vpp_service.fusion``): fuse() against its parts composed by hand, and the service's Fusion."""

from __future__ import annotations

import numpy as np
import pytest

from vpp_service.frame import StereoFrame
from vpp_service.fusion import Fusion, fuse, score, sparse_disparity
from vpp_service.matchers import build_matcher, fill_holes
from vpp_service.metrics import answered_metrics, compute_metrics
from vpp_service.sources.sensors import build_sensor
from vpp_service.sources.synthetic import make_scene
from vpp_service.vpp import VPPConfig, depth_to_disparity, disparity_to_depth, project


@pytest.fixture(scope="module")
def frame() -> StereoFrame:
    """A calibrated synthetic frame with ground truth, a non-occlusion mask and 5 % sparse points."""
    scene = make_scene(64, 112, seed=2, texture="weak", noise=2.0, max_disparity=24)
    return build_sensor("uniform", {"density": 0.05}).simulate(scene, seed=1)


@pytest.fixture(scope="module")
def matcher():
    return build_matcher("census-sgm", {"max_disparity": 32})


def test_fuse_with_vpp_is_project_then_match(frame, matcher):
    cfg = VPPConfig()
    res = fuse(frame, matcher, cfg, seed=5)
    painted = project(frame.left, frame.right, frame.sparse_disparity, cfg, seed=5)
    disp = matcher.compute(painted.left, painted.right)
    np.testing.assert_array_equal(res.left_vpp, painted.left)
    np.testing.assert_array_equal(res.right_vpp, painted.right)
    np.testing.assert_array_equal(res.occluded, painted.occluded)
    np.testing.assert_array_equal(res.disparity, disp)
    assert res.vpp_stats == painted.stats.to_dict() and res.vpp_stats["projected"] > 0
    raw = compute_metrics(disp, frame.gt_disparity)  # the raw output, no *_nocc, plus the three reported numbers
    filled = compute_metrics(fill_holes(disp), frame.gt_disparity)["bad2"]
    assert res.metrics == {**raw, **answered_metrics(raw), "bad2_filled": filled}
    c = frame.calib
    np.testing.assert_array_equal(res.depth, disparity_to_depth(disp, c.f, c.baseline, c.doffs).astype(np.float32))
    assert {"vpp", "match", "process"} <= res.timing_ms.keys()
    assert res.timing_ms["process"] >= res.timing_ms["vpp"] + res.timing_ms["match"]


def test_fuse_converts_metric_depth_and_keeps_frame_timings(frame, matcher):
    c = frame.calib
    depth_only = frame.with_(sparse_disparity=None, meta={"timing_ms": {"decode": 1.5}})
    np.testing.assert_array_equal(
        sparse_disparity(depth_only), depth_to_disparity(frame.sensor_depth, c.f, c.baseline, c.doffs)
    )
    res = fuse(depth_only, matcher, VPPConfig(), seed=5, depth=False)
    ref = project(frame.left, frame.right, sparse_disparity(depth_only), VPPConfig(), seed=5)
    np.testing.assert_array_equal(res.left_vpp, ref.left)
    assert res.depth is None and res.timing_ms["decode"] == 1.5
    assert sparse_disparity(depth_only.with_(calib=None)) is None


def test_fuse_without_vpp_or_points_runs_the_raw_pair(frame, matcher):
    disp = matcher.compute(frame.left, frame.right)
    for res in (
        fuse(frame, matcher, None),
        fuse(frame.with_(sparse_disparity=None, sensor_depth=None), matcher, VPPConfig()),
    ):
        np.testing.assert_array_equal(res.disparity, disp)
        assert res.left_vpp is None and res.right_vpp is None and res.occluded is None
        assert res.vpp_stats == {} and "vpp" not in res.timing_ms


def test_fuse_protocol_fills_holes_for_scoring_only(frame, matcher):
    res = fuse(frame, matcher, None, protocol=True)
    raw = matcher.compute(frame.left, frame.right)
    assert np.isnan(raw).any()
    np.testing.assert_array_equal(res.disparity, raw)  # the output keeps its holes
    filled = fill_holes(raw)
    expected = compute_metrics(filled, frame.gt_disparity)
    expected.update(
        {f"{k}_nocc": v for k, v in compute_metrics(filled, frame.gt_disparity, mask=frame.nocc_mask).items()}
    )
    assert res.metrics == expected
    assert score(raw, frame.with_(gt_disparity=None), protocol=True) == {}


def test_fuse_guided_passes_the_points_as_hints(frame, matcher):
    res = fuse(frame, matcher, None, guide=True)
    np.testing.assert_array_equal(res.disparity, matcher.compute(frame.left, frame.right, hints=frame.sparse_disparity))
    assert not np.array_equal(res.disparity, matcher.compute(frame.left, frame.right), equal_nan=True)
    with pytest.raises(ValueError, match="no sparse points"):
        fuse(frame.with_(sparse_disparity=None, sensor_depth=None), matcher, None, guide=True)
    with pytest.raises(ValueError, match="guidance"):
        fuse(frame, build_matcher("sgbm", {"max_disparity": 32}), None, guide=True)


def test_service_fusion_seeds_with_seq_and_counts(frame, matcher):
    fusion = Fusion(matcher, VPPConfig(), seed=100)
    res = fusion(frame.with_(seq=7))
    ref = fuse(frame, matcher, VPPConfig(), seed=107)
    np.testing.assert_array_equal(res.left_vpp, ref.left_vpp)
    np.testing.assert_array_equal(res.disparity, ref.disparity)
    fusion(frame.with_(sparse_disparity=None, sensor_depth=None))
    assert fusion.counters == {"vpp": 1, "no_depth": 1}
    plain = Fusion(matcher, None)
    plain(frame)  # points present: neither counter
    plain(frame.with_(sparse_disparity=np.full(frame.shape, np.nan, np.float32), sensor_depth=None))
    assert plain.counters == {"vpp": 0, "no_depth": 1}


def test_service_fusion_rejects_bad_arguments(matcher):
    with pytest.raises(TypeError, match="Matcher"):
        Fusion(object())
    with pytest.raises(TypeError, match="VPPConfig"):
        Fusion(matcher, {"alpha": 0.4})


def test_service_fusion_auto_range_follows_the_scene():
    from vpp_service.matchers.disparity_range import AutoRangeOptions

    sensor = build_sensor("uniform", {"density": 0.05})
    near = sensor.simulate(make_scene(64, 240, seed=3, max_disparity=70), seed=1)
    far = sensor.simulate(make_scene(64, 240, seed=3, max_disparity=12), seed=1)
    template = build_matcher("sgbm", {"max_disparity": 16})
    d = {}
    for name, fr in (("near", near), ("far", far)):
        fusion = Fusion(template, VPPConfig(), disparity_range=AutoRangeOptions())
        res = fusion(fr)
        d[name] = fusion.max_disparity
        top = float(np.nanmax(sparse_disparity(fr)))
        assert d[name] == 16 * int(np.ceil((top + 16) / 16))  # largest point + margin, rounded up to 16
        fixed = fuse(fr, build_matcher("sgbm", {"max_disparity": d[name]}), VPPConfig(), seed=fr.seq)
        np.testing.assert_array_equal(res.disparity, fixed.disparity)  # the matcher ran with that range
    assert d["near"] > d["far"] and d["near"] >= 80
    # the metric-depth-only frame gives the same range (converted with its calibration)
    depth_only = near.with_(sparse_disparity=None)
    fusion = Fusion(template, VPPConfig(), disparity_range=AutoRangeOptions())
    fusion(depth_only)
    assert fusion.max_disparity == d["near"]
    # a fixed integer is honoured: no auto range, the matcher as given
    plain = Fusion(template, VPPConfig())
    plain(near)
    assert plain.max_disparity == 16 and plain.range is None


def test_see_through_filter_runs_on_lidar_like_frames_and_is_counted(frame, matcher):
    from vpp_service.vpp.see_through import DepthFilter, filter_see_through

    cfg = VPPConfig()
    plain = fuse(frame, matcher, cfg, seed=5)
    assert plain.see_through is None and "depth_filter" not in plain.timing_ms  # not LiDAR-like: untouched
    lidar = frame.with_(meta={**frame.meta, "lidar_like": True})
    res = fuse(lidar, matcher, cfg, seed=5)
    kept, dropped = filter_see_through(frame.sparse_disparity)
    assert res.see_through == dropped > 0 and "depth_filter" in res.timing_ms
    painted = project(frame.left, frame.right, kept, cfg, seed=5)
    assert res.vpp_stats == painted.stats.to_dict()
    np.testing.assert_array_equal(res.disparity, matcher.compute(painted.left, painted.right))
    # guidance gets the filtered points too; none / see-through modes override the frame's declaration
    guided = fuse(lidar, matcher, None, guide=True)
    np.testing.assert_array_equal(guided.disparity, matcher.compute(frame.left, frame.right, hints=kept))
    assert fuse(lidar, matcher, cfg, depth_filter=None).see_through is None
    assert fuse(lidar, matcher, cfg, depth_filter=DepthFilter(mode="none")).see_through is None
    assert fuse(frame, matcher, cfg, depth_filter=DepthFilter(mode="see-through")).see_through == dropped
    # metric depth only (a ROS 2 cloud's form): converted, then filtered
    c = frame.calib
    z = disparity_to_depth(frame.sparse_disparity, c.f, c.baseline, c.doffs)
    cloud_like = lidar.with_(sparse_disparity=None, sensor_depth=np.nan_to_num(z, nan=0.0).astype(np.float32))
    assert fuse(cloud_like, matcher, cfg).see_through == filter_see_through(sparse_disparity(cloud_like))[1]


def test_service_fusion_passes_its_filter(frame, matcher):
    from vpp_service.vpp.see_through import DepthFilter

    lidar = frame.with_(meta={**frame.meta, "lidar_like": True})
    assert Fusion(matcher, VPPConfig())(lidar).see_through > 0
    assert Fusion(matcher, VPPConfig(), depth_filter=None)(lidar).see_through is None
    wide = Fusion(matcher, VPPConfig(), depth_filter=DepthFilter(window_w=31, window_h=31))(lidar).see_through
    assert wide > Fusion(matcher, VPPConfig())(lidar).see_through
    with pytest.raises(TypeError, match="depth_filter"):
        Fusion(matcher, depth_filter="auto")


def test_fuse_with_a_depth_clip_clips_before_depth_and_metrics(frame, matcher):
    from vpp_service.matchers.depth_clip import DepthClip

    c = frame.calib
    clip = DepthClip(max_depth_m=c.f * c.baseline / 12.0)  # nothing beyond 12 px
    raw = fuse(frame, matcher, VPPConfig(), seed=5)
    res = fuse(frame, matcher, VPPConfig(), seed=5, depth_clip=clip)
    expect = clip.apply(raw.disparity.copy(), matcher, c)
    assert np.isfinite(raw.disparity).sum() > np.isfinite(expect).sum() > 0
    np.testing.assert_array_equal(res.disparity, expect)
    np.testing.assert_array_equal(np.isnan(res.depth), np.isnan(expect))
    assert res.metrics == score(expect, frame)
    np.testing.assert_array_equal(
        Fusion(matcher, VPPConfig(), depth_clip=clip)(frame).disparity,
        fuse(frame, matcher, VPPConfig(), seed=frame.seq, depth_clip=clip).disparity,
    )
    with pytest.raises(TypeError, match="depth_clip"):
        Fusion(matcher, depth_clip={"max_depth_m": 3.0})


def test_fuse_with_confidence_carries_the_matchers_map_with_the_clips_holes(frame, matcher):
    """confidence=True: the matcher's compute_with_confidence on the painted pair, 0 where the depth clip cut."""
    from vpp_service.matchers.depth_clip import DepthClip

    cfg = VPPConfig()
    assert fuse(frame, matcher, cfg, seed=5).confidence is None  # not asked: not computed
    painted = project(frame.left, frame.right, frame.sparse_disparity, cfg, seed=5)
    disp, conf = matcher.compute_with_confidence(painted.left, painted.right)
    res = fuse(frame, matcher, cfg, seed=5, confidence=True)
    np.testing.assert_array_equal(res.disparity, disp)
    np.testing.assert_array_equal(res.confidence, conf)
    assert res.confidence.dtype == np.float32 and 0 < res.confidence.max() <= 1
    c = frame.calib
    clip = DepthClip(max_depth_m=c.f * c.baseline / 12.0)  # nothing beyond 12 px
    clipped = fuse(frame, matcher, cfg, seed=5, confidence=True, depth_clip=clip)
    cut = np.isfinite(disp) & np.isnan(clipped.disparity)
    assert cut.any() and np.all(clipped.confidence[cut] == 0)
    np.testing.assert_array_equal(clipped.confidence[~cut], conf[~cut])
    assert Fusion(matcher, cfg, confidence=True)(frame).confidence is not None


def test_min_confidence_of_the_matcher_makes_holes_in_fuse(frame):
    """The matcher's min_confidence applies in fuse whether or not the map is asked for."""
    loose = build_matcher("census-sgm", {"max_disparity": 32})
    strict = build_matcher("census-sgm", {"max_disparity": 32, "min_confidence": 0.5})
    full = fuse(frame, loose, VPPConfig(), seed=5, confidence=True)
    held = fuse(frame, strict, VPPConfig(), seed=5)
    want = np.where(full.confidence >= 0.5, full.disparity, np.nan)
    np.testing.assert_array_equal(held.disparity, want)
    assert np.isfinite(full.disparity).sum() > np.isfinite(held.disparity).sum() > 0
