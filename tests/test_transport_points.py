"""wire.points_to_maps (Cython scatter) against a literal NumPy reference; validation order; edge cases."""

from __future__ import annotations

import numpy as np
import pytest

from vpp_service.frame import Calibration
from vpp_service.transport import _points, wire
from vpp_service.vpp import depth_to_disparity


def reference_maps(uv, vals, h, w, keep, calib=None):
    """Literal version of points_to_maps.

    Check all coordinates, then bounds, then values; round with numpy.rint; write the
    points sorted so that the winner of each pixel comes last.
    """
    uv = np.asarray(uv, np.float32).reshape(-1, 2)
    vals = np.asarray(vals, np.float32)
    if len(vals):
        if not np.isfinite(uv).all():
            raise wire.WireError("depth.uv: coordinates must be finite")
        x, y = uv[:, 0], uv[:, 1]
        if (
            (x < np.float32(-0.5)).any()
            or (x >= np.float32(w - 0.5)).any()
            or (y < np.float32(-0.5)).any()
            or (y >= np.float32(h - 0.5)).any()
        ):
            raise wire.WireError(f"depth.uv: points must lie inside the {w}x{h} left image")
        if not (np.isfinite(vals).all() and (vals > 0).all()):
            raise wire.WireError("depth.z: values must be finite and > 0")
    idx = np.rint(uv[:, 1]).astype(np.int64) * w + np.rint(uv[:, 0]).astype(np.int64)
    order = np.argsort(-vals if keep == "min" else vals, kind="stable")
    out = np.full(h * w, np.nan, np.float32)
    out[idx[order]] = vals[order]
    out = out.reshape(h, w)
    if calib is None or keep != "min":
        return out, None
    return out, depth_to_disparity(out, calib.f, calib.baseline, calib.doffs)


CALIB = Calibration(f=700.0, baseline=0.54, doffs=3.0)


def random_points(seed, h, w, n, collide):
    rng = np.random.default_rng(seed)
    if collide:  # few distinct pixels, many points each, exact .5 positions included
        xs = rng.integers(0, w, n) + rng.choice([-0.5, -0.25, 0.0, 0.25, 0.5], n)
        ys = rng.integers(0, h, n) + rng.choice([-0.5, 0.0, 0.49], n)
        xs, ys = np.clip(xs, -0.5, w - 0.51), np.clip(ys, -0.5, h - 0.51)
    else:
        xs, ys = rng.uniform(-0.5, w - 0.5, n), rng.uniform(-0.5, h - 0.5, n)
    uv = np.stack([xs, ys], 1).astype(np.float32)
    vals = (
        rng.choice(np.float32([0.5, 1.0, 2.0, 7.5, 300.0]), n)
        if collide
        else rng.uniform(0.1, 400.0, n).astype(np.float32)
    )
    return uv, vals


@pytest.mark.parametrize(("keep", "calib"), [("min", None), ("min", CALIB), ("max", None)])
@pytest.mark.parametrize("collide", [False, True])
@pytest.mark.parametrize("seed", range(6))
def test_equals_reference(seed, collide, keep, calib):
    h, w = (5, 7) if collide else (37, 53)
    uv, vals = random_points(seed, h, w, 60 if collide else 400, collide)
    got = wire.points_to_maps(uv, vals, h, w, keep, calib=calib)
    want = reference_maps(uv, vals, h, w, keep, calib)
    np.testing.assert_array_equal(got[0], want[0])  # NaN positions equal too
    if want[1] is None:
        assert got[1] is None
    else:
        np.testing.assert_array_equal(got[1], want[1])


@pytest.mark.parametrize("collide", [False, True])
@pytest.mark.parametrize("seed", range(6))
def test_disparity_alone_equals_reference(seed, collide):
    """values_map=False: no metric map, and the disparity map the reference derives from its metric map."""
    h, w = (5, 7) if collide else (37, 53)
    uv, vals = random_points(seed, h, w, 60 if collide else 400, collide)
    depth, disp = wire.points_to_maps(uv, vals, h, w, "min", calib=CALIB, values_map=False)
    assert depth is None
    np.testing.assert_array_equal(disp, reference_maps(uv, vals, h, w, "min", CALIB)[1])


@pytest.mark.parametrize("keep", ["min", "max"])
def test_disparity_alone_needs_metric_points_and_calib(keep):
    uv, vals = np.zeros((1, 2), np.float32), np.ones(1, np.float32)
    calib = CALIB if keep == "max" else None
    with pytest.raises(ValueError, match="values_map"):
        wire.points_to_maps(uv, vals, 2, 2, keep, calib=calib, values_map=False)
    with pytest.raises(ValueError, match="out may be 0 x 0"):
        _points.scatter_points(
            uv.reshape(-1), vals, keep == "min", np.empty((0, 0), np.float32), np.empty((0, 0), np.float32), 1.0, 0.0
        )


def test_disparity_left_out_where_not_positive():
    """D = f b / z - doffs <= 0 for far points: NaN, like depth_to_disparity."""
    uv = np.float32([[0, 0], [1, 0], [2, 0]])
    z = np.float32([1.0, 700 * 0.54 / 3.0, 1000.0])  # d = 375, exactly 0, < 0
    depth, disp = wire.points_to_maps(uv, z, 1, 3, "min", calib=CALIB)
    np.testing.assert_array_equal(depth, z[None])
    assert disp[0, 0] == np.float32(700 * 0.54 / 1.0 - 3.0) and np.isnan(disp[0, 1:]).all()


def test_rounding_half_to_even_and_nearest_wins():
    uv = np.float32([[0.5, 0.0], [1.5, 0.0], [2.5, 0.0], [2.4, 0.0]])
    vals = np.float32([4.0, 5.0, 6.0, 3.0])
    out = wire.points_to_maps(uv, vals, 1, 4, "min")[0]
    # 0.5 -> 0, 1.5 -> 2, 2.5 -> 2, 2.4 -> 2: pixel 2 keeps the smallest of 5, 6, 3
    np.testing.assert_array_equal(out, np.float32([[4.0, np.nan, 3.0, np.nan]]))
    out = wire.points_to_maps(uv, vals, 1, 4, "max")[0]
    np.testing.assert_array_equal(out, np.float32([[4.0, np.nan, 6.0, np.nan]]))


def test_empty():
    depth, disp = wire.points_to_maps(np.zeros((0, 2), np.float32), np.zeros(0, np.float32), 3, 4, "min", calib=CALIB)
    assert np.isnan(depth).all() and np.isnan(disp).all() and depth.shape == (3, 4)


@pytest.mark.parametrize(
    ("uv", "vals", "match"),
    [
        ([[np.nan, 0]], [1.0], "finite"),
        ([[0, np.inf]], [1.0], "finite"),
        ([[-0.51, 0]], [1.0], "inside"),
        ([[3.5, 0]], [1.0], "inside"),  # w = 4: x must be < 3.5
        ([[0, 2.5]], [1.0], "inside"),  # h = 3
        ([[0, 0]], [0.0], "> 0"),
        ([[0, 0]], [-1.0], "> 0"),
        ([[0, 0]], [np.nan], "> 0"),
        ([[0, 0]], [np.inf], "> 0"),
        # order of the checks over all points: coordinates, then bounds, then values
        ([[0, 0], [9, 0], [np.nan, 0]], [-1.0, 1.0, 1.0], "finite"),
        ([[0, 0], [9, 0]], [-1.0, 1.0], "inside"),
    ],
)
def test_bad_points(uv, vals, match):
    uv, vals = np.float32(uv), np.float32(vals)
    with pytest.raises(wire.WireError, match=match):
        wire.points_to_maps(uv, vals, 3, 4, "min")
    with pytest.raises(wire.WireError, match=match):
        wire.points_to_maps(uv, vals, 3, 4, "min", calib=CALIB, values_map=False)
    with pytest.raises(wire.WireError, match=match):
        reference_maps(uv, vals, 3, 4, "min")


def test_rejects_unknown_keep_rule():
    with pytest.raises(ValueError, match="keep"):
        wire.points_to_maps(np.zeros((1, 2), np.float32), np.ones(1, np.float32), 2, 2, "first")


def test_kernel_reports_all_problems_and_checks_sizes():
    uv = np.float32([np.nan, 0, 9, 0, 0, 0])
    out = np.full((3, 4), np.nan, np.float32)
    bad = _points.scatter_points(uv, np.float32([1, 1, -1]), True, out, np.empty((0, 0), np.float32), 0.0, 0.0)
    assert bad == _points.BAD_UV | _points.OUTSIDE | _points.BAD_VALUE
    with pytest.raises(ValueError, match="uv"):
        _points.scatter_points(uv[:4], np.float32([1, 1, 1]), True, out, np.empty((0, 0), np.float32), 0.0, 0.0)
    with pytest.raises(ValueError, match="out_d"):
        _points.scatter_points(uv, np.float32([1, 1, 1]), True, out, np.empty((2, 2), np.float32), 1.0, 0.0)
