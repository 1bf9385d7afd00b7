"""OpenCV matchers: the left band of ``max_disparity`` columns gets disparities (``left_band``)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from vpp_service.matchers import build_matcher
from vpp_service.settings import SettingsError

SHIFT = 9
D = 48


@pytest.fixture(scope="module")
def pair() -> tuple[np.ndarray, np.ndarray]:
    """Textured gray pair 60 x 200: the right view is the left shifted by SHIFT px."""
    rng = np.random.default_rng(3)
    tex = cv2.GaussianBlur(rng.uniform(0, 255, (60, 200 + SHIFT)), (0, 0), 1.0)
    tex = np.clip((tex - tex.mean()) * 4 + 128, 0, 255).astype(np.uint8)
    return np.ascontiguousarray(tex[:, :200]), np.ascontiguousarray(tex[:, SHIFT:])


@pytest.mark.parametrize("name", ["sgbm", "bm"])
def test_left_band_gets_disparities(pair, name):
    left, right = pair
    band = slice(SHIFT + 8, D)  # pixels of the band whose match lies inside the right image (past the block)
    off = build_matcher(name, {"max_disparity": D, "left_band": "off"}).compute(left, right)
    assert np.isnan(off[:, :D]).all()  # OpenCV's own empty band
    for mode in ("replicate", "constant"):
        disp = build_matcher(name, {"max_disparity": D, "left_band": mode}).compute(left, right)
        assert disp.shape == left.shape
        inner = disp[8:-8, band]
        assert np.isfinite(inner).mean() > 0.9, mode
        assert np.nanmedian(np.abs(inner - SHIFT)) < 0.5, mode
        # outside the band the padding changes nothing the matcher can see
        a, b = disp[8:-8, D + 16 : -16], off[8:-8, D + 16 : -16]
        both = np.isfinite(a) & np.isfinite(b)
        assert both.mean() > 0.8
        assert np.abs(a[both] - b[both]).max() <= 1.0


@pytest.mark.parametrize("name", ["sgbm", "bm"])
def test_left_band_default_and_bad_value(name):
    assert build_matcher(name).options.left_band == "replicate"
    with pytest.raises(SettingsError, match="left_band"):
        build_matcher(name, {"left_band": "wrap"})
