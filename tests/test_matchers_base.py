"""Matcher registry, options validation, input contract and the census-SGM cost-volume API."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from vpp_service.matchers import MATCHERS, Matcher, build_matcher
from vpp_service.matchers.census_sgm import CensusSGM, CensusSGMOptions
from vpp_service.matchers.opencv import opencv_num_disparities
from vpp_service.settings import SettingsError

NAMES = ["bm", "census-sgm", "sgbm"]


@pytest.fixture(scope="module")
def pair():
    """Small textured RGB pair: right = left shifted by 6 px."""
    rng = np.random.default_rng(0)
    tex = cv2.GaussianBlur(rng.uniform(0, 255, (40, 110)), (0, 0), 1.0)
    tex = np.clip((tex - tex.mean()) * 4 + 128, 0, 255).astype(np.uint8)
    left = tex[:, 0:100]
    right = tex[:, 6:106]
    rgb = lambda g: np.ascontiguousarray(np.repeat(g[:, :, None], 3, axis=2))  # noqa: E731
    return rgb(left), rgb(right)


def test_registry_names():
    assert MATCHERS.names() == sorted([*NAMES, "onnx", "psmnet"])  # the networks: tests/test_matchers_onnx.py
    with pytest.raises(ValueError, match="known: bm, census-sgm, onnx, psmnet, sgbm"):
        build_matcher("nope")


@pytest.mark.parametrize("name", NAMES)
def test_build_and_smoke(pair, name):
    m = build_matcher(name, {"max_disparity": 16})
    assert isinstance(m, Matcher) and m.name == name
    assert m.options.max_disparity == 16 and m.options.fill is False
    assert m.supports_guidance is (name == "census-sgm")
    left, right = pair
    disp = m.compute(left, right)
    assert disp.shape == left.shape[:2] and disp.dtype == np.float32
    assert np.nanmedian(disp) == pytest.approx(6.0, abs=0.5)
    assert np.isnan(disp).any() and not np.isinf(disp).any()


@pytest.mark.parametrize("name", NAMES)
def test_gray_and_single_channel_inputs(pair, name):
    left, right = pair
    m = build_matcher(name, {"max_disparity": 16})
    g = m.compute(np.ascontiguousarray(left[:, :, 0]), np.ascontiguousarray(right[:, :, 0]))
    g1 = m.compute(np.ascontiguousarray(left[:, :, :1]), np.ascontiguousarray(right[:, :, :1]))
    np.testing.assert_array_equal(g, g1)
    if name != "sgbm":  # sgbm matches colour; the others convert to gray, identical here
        np.testing.assert_array_equal(g, m.compute(left, right))


@pytest.mark.parametrize("name", NAMES)
def test_fill_option(pair, name):
    left, right = pair
    disp = build_matcher(name, {"max_disparity": 16, "fill": True}).compute(left, right)
    rows = ~np.isnan(build_matcher(name, {"max_disparity": 16}).compute(left, right)).all(axis=1)
    assert not np.isnan(disp[rows]).any()


def test_defaults_and_options_instance():
    assert build_matcher("census-sgm").options == CensusSGMOptions()
    o = CensusSGMOptions(max_disparity=32, paths=4)
    assert CensusSGM(o).options is o
    assert CensusSGM({"max_disparity": 32}).options.max_disparity == 32
    assert CensusSGM(None).options.max_disparity == 128
    with pytest.raises(TypeError, match="options"):
        CensusSGM(42)


@pytest.mark.parametrize(
    ("name", "opts", "match"),
    [
        ("sgbm", {"foo": 1}, "matcher.sgbm.foo: got an unknown option; expected one of block_size, "),
        ("census-sgm", {"max_disparity": 0}, "max_disparity"),
        ("census-sgm", {"max_disparity": -5}, "max_disparity"),
        ("census-sgm", {"max_disparity": 12.5}, "max_disparity"),
        ("census-sgm", {"paths": 6}, "paths"),
        ("census-sgm", {"uniqueness": 1.5}, "uniqueness"),
        ("census-sgm", {"p1": 99999}, "p1"),
        ("census-sgm", {"guided_k": 0.0}, "guided_k"),
        ("census-sgm", {"lr_tolerance": -1.0}, "lr_tolerance"),
        ("census-sgm", {"border_margin": -1}, "border_margin"),
        ("census-sgm", {"border_margin": 2.5}, "border_margin"),
        ("census-sgm", {"gap_size": -1}, "gap_size"),
        ("census-sgm", {"gap_size": True}, "gap_size"),
        ("census-sgm", {"threads": -1}, "threads"),
        ("census-sgm", {"fill": "yes"}, "fill"),
        ("sgbm", {"mode": "fast"}, "mode"),
        ("sgbm", {"block_size": 4}, "block_size"),
        ("sgbm", {"p1": 10, "p2": 5}, "p2"),
        ("bm", {"block_size": 3}, "block_size"),
        ("bm", {"pre_filter": "none"}, "pre_filter"),
        ("bm", {"pre_filter_cap": 64}, "pre_filter_cap"),
    ],
)
def test_bad_options(name, opts, match):
    with pytest.raises(SettingsError, match=match):
        build_matcher(name, opts)


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize(
    ("make", "exc", "match"),
    [
        (lambda left, right: (left, right[:-1]), ValueError, "same shape"),
        (lambda left, right: (left.astype(np.float32), right), TypeError, "left must be uint8"),
        (lambda left, right: (left, right.astype(np.uint16)), TypeError, "right must be uint8"),
        (lambda left, right: (left[:, ::2], right[:, ::2]), ValueError, "contiguous"),
        (lambda left, right: (np.zeros((4, 5, 4), np.uint8), np.zeros((4, 5, 4), np.uint8)), ValueError, "C in"),
        (lambda left, right: (np.zeros((0, 5), np.uint8), np.zeros((0, 5), np.uint8)), ValueError, "empty"),
        (lambda left, right: (left.tolist(), right), TypeError, "numpy array"),
        (
            lambda left, right: (np.ascontiguousarray(left[:, :12]), np.ascontiguousarray(right[:, :12])),
            ValueError,
            "width",
        ),
    ],
)
def test_bad_images(pair, name, make, exc, match):
    m = build_matcher(name, {"max_disparity": 16})
    left, right = make(*pair)
    with pytest.raises(exc, match=match):
        m.compute(left, right)


def test_opencv_rounding_and_width():
    assert [opencv_num_disparities(v) for v in (1, 16, 17, 100, 128)] == [16, 16, 32, 112, 128]
    img = np.zeros((20, 40), np.uint8)
    for name in ("sgbm", "bm"):  # 30 < 40, but OpenCV would search 32 + block: rounded value must fit
        with pytest.raises(ValueError, match="rounded up to 48"):
            build_matcher(name, {"max_disparity": 33}).compute(img, img)


def test_hints_rejected_without_guidance(pair):
    left, right = pair
    hints = np.full(left.shape[:2], 6.0, np.float32)
    with pytest.raises(ValueError, match="does not support guidance"):
        build_matcher("sgbm", {"max_disparity": 16}).compute(left, right, hints=hints)


@pytest.mark.parametrize(
    ("hints", "exc", "match"),
    [
        (np.zeros((3, 3), np.float32), ValueError, "hints must have shape"),
        (np.zeros((40, 100), np.int32), TypeError, "float"),
        (np.full((40, 100), np.inf, np.float32), ValueError, "inf"),
        ([[1.0]], TypeError, "numpy"),
    ],
)
def test_bad_hints(pair, hints, exc, match):
    with pytest.raises(exc, match=match):
        build_matcher("census-sgm", {"max_disparity": 16}).compute(*pair, hints=hints)


def test_cost_volume_api_equals_compute(pair):
    left, right = pair
    m = build_matcher("census-sgm", {"max_disparity": 16})
    cost = m.cost_volume(left, right)
    assert cost.shape == (40, 100, 16) and cost.dtype == np.uint16 and cost.max() <= 24
    np.testing.assert_array_equal(m.compute_from_cost(cost, left), m.compute(left, right))
    hints = np.full(left.shape[:2], np.nan, np.float32)
    hints[::7, ::5] = 6.0
    before = cost.copy()
    guided = m.compute_from_cost(cost, left[:, :, 0].copy(), hints=hints)
    np.testing.assert_array_equal(cost, before)  # not modified
    np.testing.assert_array_equal(guided, m.compute(left, right, hints=hints))
    with pytest.raises(ValueError, match="left_gray"):
        m.compute_from_cost(cost, left[:20].copy())
    with pytest.raises(TypeError, match="cost must be uint16"):
        m.compute_from_cost(cost.astype(np.float32), left)


def test_guidance_pulls_towards_hints(pair):
    """With a (wrong) dense hint the modulated minimum wins: guided output follows it.

    The right view gets noise: on the exact pair the true match costs 0, which stays 0 after the
    modulation and ties with the hint.
    """
    left, right = pair
    noise = np.random.default_rng(0).integers(-6, 7, right.shape)
    right = np.clip(right.astype(np.int16) + noise, 0, 255).astype(np.uint8)
    m = build_matcher("census-sgm", {"max_disparity": 16, "lr_check": False})
    hints = np.full(left.shape[:2], 9.0, np.float32)
    disp = m.compute(left, right, hints=hints)
    assert np.nanmedian(disp) == pytest.approx(9.0, abs=0.5)


@pytest.mark.parametrize("threads", [1, 2])
def test_census_sgm_thread_count_does_not_change_result(pair, threads):
    left, right = pair
    ref = build_matcher("census-sgm", {"max_disparity": 16, "threads": 1}).compute(left, right)
    got = build_matcher("census-sgm", {"max_disparity": 16, "threads": threads}).compute(left, right)
    np.testing.assert_array_equal(got, ref)


def test_check_disparity_strict_kernel_input_or_converted():
    from vpp_service.matchers.inputs import check_disparity

    a = np.array([[1.0, np.nan, 3.0], [4.0, 5.0, 6.0]])
    got = check_disparity(a[:, ::2], "d", (2, 2), convert=True)  # float64, strided: converted
    assert got.dtype == np.float32 and got.flags.c_contiguous
    np.testing.assert_array_equal(got, a[:, ::2].astype(np.float32))
    f32 = a.astype(np.float32)
    assert check_disparity(f32, "d") is f32  # a kernel input: unchanged
    for bad, exc, match in [
        (a, TypeError, "d must be float32"),
        (f32[:, ::2], ValueError, "contiguous"),
        (np.full((2, 3), np.inf, np.float32), ValueError, "inf"),
        (f32[None], ValueError, "2-D"),
        (np.zeros((2, 3), np.int16), TypeError, "float"),
    ]:
        with pytest.raises(exc, match=match):
            check_disparity(bad, "d")
    with pytest.raises(ValueError, match="d must have shape"):
        check_disparity(f32, "d", (3, 2), convert=True)
