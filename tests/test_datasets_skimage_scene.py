"""The scikit-image Motorcycle scene: one loader (NaN rule, calibration) for the demo and the simulator."""

from __future__ import annotations

import numpy as np
import pytest

from vpp_service.datasets.skimage_scene import MOTORCYCLE_CALIB, motorcycle, motorcycle_arrays


def test_motorcycle_nan_rule_and_calibration():
    import skimage.data

    left, right, raw = skimage.data.stereo_motorcycle()
    fr = motorcycle()
    np.testing.assert_array_equal(fr.left, left)
    np.testing.assert_array_equal(fr.right, right)
    gt = fr.gt_disparity
    assert gt.dtype == np.float32 and fr.calib == MOTORCYCLE_CALIB and fr.name == "motorcycle"
    usable = np.isfinite(raw) & (raw > 0)
    assert np.isnan(gt[~usable]).all() and (~usable).any()  # +inf (and <= 0) -> NaN
    np.testing.assert_array_equal(gt[usable], raw[usable])
    with pytest.raises(ValueError, match="read-only"):
        gt[0, 0] = 1.0  # the cached arrays are read-only


def test_simulator_and_demo_share_the_loader():
    from vpp_service.sources.sim import motorcycle_frame

    fr = motorcycle_frame()
    left, _, disp = motorcycle_arrays()
    assert fr.left is left and fr.gt_disparity is disp
