"""The see-through filter against a plain Python reference, its settings and its input checks."""

from __future__ import annotations

import numpy as np
import pytest

from vpp_service.vpp.see_through import DepthFilter, filter_see_through

N = np.nan


def reference(a, window_w, window_h, margin, min_gap):
    """Plain implementation: every point against the points of the four sides of its clipped window."""
    a = np.asarray(a, np.float32)
    h, w = a.shape
    point = np.isfinite(a) & (a > 0)
    out = np.full((h, w), np.nan, np.float32)
    dropped = 0
    rx, ry = window_w // 2, window_h // 2

    def nearer(t, y0, y1, x0, x1):  # any point > t in rows [y0, y1) x columns [x0, x1), clipped
        y0, y1, x0, x1 = max(0, y0), min(h, y1), max(0, x0), min(w, x1)
        win = a[y0:y1, x0:x1][point[y0:y1, x0:x1]]
        return bool(np.any(win > t))

    for y in range(h):
        for x in range(w):
            if not point[y, x]:
                continue
            d = a[y, x]
            t = max(d * np.float32(1 + margin), d + np.float32(min_gap))
            left = nearer(t, y - ry, y + ry + 1, x - rx, x)
            right = nearer(t, y - ry, y + ry + 1, x + 1, x + rx + 1)
            above = nearer(t, y - ry, y, x - rx, x + rx + 1)
            below = nearer(t, y + 1, y + ry + 1, x - rx, x + rx + 1)
            if (left and right) or (above and below):
                dropped += 1
            else:
                out[y, x] = d
    return out, dropped


def random_map(rng, h, w, density, values):
    a = np.full((h, w), np.nan, np.float32)
    have = rng.random((h, w)) < density
    a[have] = rng.choice(values, have.sum()) if values is not None else rng.uniform(0.5, 60, have.sum())
    a[rng.random((h, w)) < 0.03] = np.inf
    a[rng.random((h, w)) < 0.03] = -2.0
    a[rng.random((h, w)) < 0.03] = 0.0
    return a


@pytest.mark.parametrize("seed", range(12))
@pytest.mark.parametrize(("window_w", "window_h"), [(1, 1), (3, 1), (1, 5), (7, 15), (5, 41), (31, 3)])
@pytest.mark.parametrize(("margin", "min_gap"), [(0.0, 0.0), (0.1, 1.0), (1.0, 0.0)])
def test_matches_reference(seed, window_w, window_h, margin, min_gap):
    rng = np.random.default_rng(seed)
    h, w = (int(v) for v in rng.integers(1, 40, 2))
    # few distinct values: many ties at exactly the threshold (1 * 1.1 vs 1.1 never, 10 vs 11 with gap 1 often)
    values = [1.0, 2.0, 10.0, 11.0, 20.0] if seed % 2 else None
    a = random_map(rng, h, w, rng.uniform(0.05, 0.9), values)
    got, n = filter_see_through(a, window_w, window_h, margin, min_gap)
    want, n_want = reference(a, window_w, window_h, margin, min_gap)
    assert n == n_want
    np.testing.assert_array_equal(got, want)
    assert got.dtype == np.float32


@pytest.mark.parametrize(("window_w", "window_h"), [(3, 3), (7, 15)])
def test_kitti_size_matches_reference_on_rows(window_w, window_h):
    rng = np.random.default_rng(5)
    a = random_map(rng, 40, 1242, 0.26, None)
    got, n = filter_see_through(a, window_w, window_h, 0.1, 1.0)
    want, n_want = reference(a, window_w, window_h, 0.1, 1.0)
    assert n == n_want
    np.testing.assert_array_equal(got, want)


def test_hand_case_foreground_hides_background():
    a = np.array(
        [
            [N, 30, N, 30, N, N],
            [N, N, 10, N, 10, N],
            [N, N, N, N, N, N],
            [30, 10, N, N, N, 10],
            [30, N, N, N, N, N],
        ],
        np.float32,
    )
    got, n = filter_see_through(a, window_w=3, window_h=3, margin=0.1, min_gap=1.0)
    # (1, 2): 30s left and right of it -> hidden; (1, 4): a 30 on its left only -> kept (a visible
    # background point beside an edge); (3, 1): 30s on its left only -> kept; (3, 5): alone -> kept
    assert n == 1
    want = a.copy()
    want[1, 2] = N
    np.testing.assert_array_equal(got, want)
    # above and below also count as opposite sides
    col = np.array([[30], [10], [30]], np.float32)
    assert filter_see_through(col, 1, 3)[1] == 1 and filter_see_through(col[:2], 1, 3)[1] == 0


def test_ties_and_margins():
    a = np.array([[11.0, 10.0, 11.0]], np.float32)
    assert filter_see_through(a, 3, 1, margin=0.1, min_gap=0.0)[1] == 0  # 11 is not > 10 * 1.1
    assert filter_see_through(a, 3, 1, margin=0.0, min_gap=1.0)[1] == 0  # 11 is not > 10 + 1
    assert filter_see_through(a, 3, 1, margin=0.05, min_gap=0.5)[1] == 1


@pytest.mark.parametrize(
    "a",
    [
        np.full((4, 5), np.nan, np.float32),
        np.zeros((3, 3), np.float32),
        np.full((2, 2), np.inf, np.float32),
        np.full((1, 1), 5.0, np.float32),
    ],
    ids=["all-nan", "all-zero", "all-inf", "one-point"],
)
def test_maps_without_neighbours(a):
    got, n = filter_see_through(a)
    assert n == 0
    point = np.isfinite(a) & (a > 0)
    np.testing.assert_array_equal(np.isfinite(got), point)
    np.testing.assert_array_equal(got[point], a[point])


def test_borders_clip_the_window():
    a = np.full((5, 5), np.nan, np.float32)
    a[0, 2], a[4, 0], a[4, 4] = 5.0, 50.0, 50.0
    assert filter_see_through(a, 9, 9)[1] == 1  # both 50s inside the 5's clipped window, left and right
    assert filter_see_through(a, 3, 9)[1] == 0  # 2 columns apart: outside a 3-wide window
    assert filter_see_through(a, 9, 7)[1] == 0  # 4 rows apart: outside a 7-high window
    a[4, 4] = np.nan
    assert filter_see_through(a, 9, 9)[1] == 0  # one side only: the border adds no side


def test_float64_and_non_contiguous_input_and_input_untouched():
    a = np.array([[50.0, 5.0, 50.0]], np.float64)
    before = a.copy()
    got, n = filter_see_through(a, 3, 1)
    assert got.dtype == np.float32 and n == 1
    np.testing.assert_array_equal(a, before)
    b = np.asfortranarray(np.array([[50.0, 5.0, 50.0], [5.0, 50.0, 5.0]], np.float32))
    assert filter_see_through(b, 3, 1)[1] == 1
    assert filter_see_through(b[:, ::-1], 3, 3)[1] == filter_see_through(np.ascontiguousarray(b[:, ::-1]), 3, 3)[1]


@pytest.mark.parametrize(
    ("a", "kwargs", "error", "match"),
    [
        ([[1.0]], {}, TypeError, "numpy.ndarray"),
        (np.ones((2, 2), np.int32), {}, TypeError, "dtype"),
        (np.ones(4, np.float32), {}, ValueError, "2-D"),
        (np.ones((0, 3), np.float32), {}, ValueError, "empty"),
        (np.ones((2, 2), np.float32), {"window_w": 4}, ValueError, "window_w"),
        (np.ones((2, 2), np.float32), {"window_h": 0}, ValueError, "window_h"),
        (np.ones((2, 2), np.float32), {"window_h": 2.0}, TypeError, "window_h"),
        (np.ones((2, 2), np.float32), {"margin": -0.1}, ValueError, "margin"),
        (np.ones((2, 2), np.float32), {"min_gap": np.nan}, ValueError, "min_gap"),
        (np.ones((2, 2), np.float32), {"margin": "0.1"}, TypeError, "margin"),
    ],
)
def test_bad_input(a, kwargs, error, match):
    with pytest.raises(error, match=match):
        filter_see_through(a, **kwargs)


def test_both_builds_agree():
    from vpp_service.vpp import _see_through, see_through

    rng = np.random.default_rng(3)
    a = random_map(rng, 50, 300, 0.3, None)
    for k in [_see_through, see_through.avx2_build()]:
        if k is None:
            continue
        out = np.empty_like(a)
        n = k.see_through_rows(a, out, 3, 7, 0.1, 1.0)
        want, n_want = reference(a, 7, 15, 0.1, 1.0)
        assert n == n_want
        np.testing.assert_array_equal(out, want)


def test_depth_filter_modes():
    lidar, other = {"lidar_like": True}, {"sensor": "uniform"}
    auto, on, off = DepthFilter(), DepthFilter(mode="see-through"), DepthFilter(mode="none")
    assert auto.applies(lidar) and not auto.applies(other)
    assert on.applies(lidar) and on.applies(other)
    assert not off.applies(lidar) and not off.applies(other)
    a = np.array([[50.0, 5.0, 50.0]], np.float32)
    f = DepthFilter(window_w=3, window_h=1)
    np.testing.assert_array_equal(f(a)[0], filter_see_through(a, 3, 1)[0])


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [({"mode": "always"}, "mode"), ({"window_w": 2}, "window_w"), ({"margin": -1.0}, "margin")],
)
def test_depth_filter_rejects_bad_settings(kwargs, match):
    with pytest.raises(ValueError, match=match):
        DepthFilter(**kwargs)
