"""Tests of the depth/disparity conversions and point-cloud projection."""

from __future__ import annotations

import numpy as np
import pytest

from vpp_service.vpp import depth_to_disparity, disparity_to_depth, points_to_depth_map


def test_depth_to_disparity_values_and_missing():
    z = np.array([[2.0, 0.0, np.nan, -1.0, np.inf]], np.float32)
    d = depth_to_disparity(z, f=100.0, baseline=0.5, doffs=5.0)
    assert d.dtype == np.float32
    assert d[0, 0] == pytest.approx(100 * 0.5 / 2.0 - 5.0)
    assert np.isnan(d[0, 1:]).all()


def test_round_trip():
    rng = np.random.default_rng(0)
    z = rng.uniform(0.5, 20, (10, 10)).astype(np.float32)
    d = depth_to_disparity(z, 700.0, 0.12, 2.0)
    np.testing.assert_allclose(disparity_to_depth(d, 700.0, 0.12, 2.0), z, rtol=1e-5)


@pytest.mark.parametrize(
    ("kwargs", "exc"),
    [
        (dict(f=0.0), ValueError),
        (dict(baseline=-1.0), ValueError),
        (dict(f="a"), TypeError),
        (dict(doffs=np.nan), ValueError),
    ],
)
def test_bad_calibration(kwargs, exc):
    args = dict(f=1.0, baseline=1.0, doffs=0.0)
    args.update(kwargs)
    with pytest.raises(exc, match=next(iter(kwargs))):
        depth_to_disparity(np.ones((2, 2), np.float32), **args)


def test_bad_maps():
    with pytest.raises(TypeError, match="depth"):
        depth_to_disparity(np.ones((2, 2), np.int32), 1.0, 1.0)
    with pytest.raises(TypeError, match="disparity"):
        disparity_to_depth([1.0], 1.0, 1.0)


def reference_depth_map(pts, K, T, shape):
    H, W = shape
    out = np.zeros(shape, np.float32)
    for p in pts:
        c = T[:3, :3] @ p + T[:3, 3]
        if not np.all(np.isfinite(c)) or c[2] <= 0:
            continue
        uvw = K @ c
        u, v = int(np.floor(uvw[0] / uvw[2] + 0.5)), int(np.floor(uvw[1] / uvw[2] + 0.5))
        if 0 <= u < W and 0 <= v < H and (out[v, u] == 0 or c[2] < out[v, u]):
            out[v, u] = c[2]
    return out


@pytest.mark.parametrize("seed", range(4))
def test_points_to_depth_map_matches_loop(seed):
    rng = np.random.default_rng(seed)
    pts = rng.uniform([-3, -2, -1], [3, 2, 20], (400, 3))
    pts[::50] = np.nan
    K = np.array([[50.0, 0, 20], [0, 50.0, 15], [0, 0, 1]])
    a = 0.1 * seed
    T = np.eye(4)
    T[:3, :3] = [[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]]
    T[:3, 3] = [0.1, -0.05, 0.3]
    out = points_to_depth_map(pts, K, T, (30, 40))
    np.testing.assert_allclose(out, reference_depth_map(pts, K, T, (30, 40)), rtol=1e-6)
    assert (out > 0).sum() > 20


def test_nearest_point_wins():
    K = np.array([[10.0, 0, 5], [0, 10.0, 5], [0, 0, 1]])
    pts = np.array([[0, 0, 4.0], [0, 0, 2.0], [0, 0, 3.0], [0, 0, -1.0]])
    out = points_to_depth_map(pts, K, np.eye(4), (10, 10))
    assert out[5, 5] == 2.0 and (out > 0).sum() == 1
    assert not points_to_depth_map(np.zeros((0, 3)), K, np.eye(4), (10, 10)).any()


@pytest.mark.parametrize(
    ("args", "exc"),
    [
        ((np.zeros((3, 2)), np.eye(3), np.eye(4), (5, 5)), ValueError),
        ((np.zeros((3, 3)), np.eye(4), np.eye(4), (5, 5)), ValueError),
        ((np.zeros((3, 3)), np.eye(3), np.eye(3), (5, 5)), ValueError),
        ((np.zeros((3, 3)), np.eye(3), np.eye(4), (0, 5)), ValueError),
        (("pts", np.eye(3), np.eye(4), (5, 5)), TypeError),
    ],
)
def test_points_bad_input(args, exc):
    with pytest.raises(exc):
        points_to_depth_map(*args)


def _depth_to_disparity_reference(z, f, b, doffs):
    """Plain whole-map float64 formula, NaN where missing or not > 0."""
    zz = z.astype(np.float64)
    ok = np.isfinite(zz) & (zz > 0)
    out = np.full(zz.shape, np.nan)
    out[ok] = f * b / zz[ok] - doffs
    out[~(out > 0)] = np.nan
    return out.astype(np.float32)


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("doffs", [0.0, 30.0])
@pytest.mark.parametrize("strided", [False, True])
def test_depth_to_disparity_matches_reference(seed, doffs, strided):
    rng = np.random.default_rng(seed)
    z = rng.uniform(-1, 50, (40, 64)).astype(np.float32)
    z[rng.random(z.shape) < 0.8] = 0
    z[0, :3] = [np.nan, np.inf, -np.inf]
    if strided:
        z = z[:, ::2]
    got = depth_to_disparity(z, 700.0, 0.5, doffs)
    np.testing.assert_array_equal(got, _depth_to_disparity_reference(z, 700.0, 0.5, doffs))
