"""The Middlebury 2014 *Motorcycle* pair shipped with scikit-image, as a :class:`StereoFrame`.

``skimage.data.stereo_motorcycle()`` gives the quarter-resolution pair
(741 x 500) and the left view's disparity with ``+inf`` = invalid. Here every
disparity that is not finite and positive becomes NaN (the project's "no
ground truth" value). scikit-image ships no calibration, so a nominal one is
attached: Middlebury's own ``calib.txt`` for Motorcycle scaled to this quarter
resolution (:data:`MOTORCYCLE_CALIB`: f = 3979.911 / 4 px, baseline = 0.193 m,
doffs = 124.343 / 4 px). Depths derived from it are plausible, not measured.

The ``demo`` command and the simulator source (``sim``, scene ``motorcycle``)
both load the scene here.
"""

from __future__ import annotations

import functools

import numpy as np

from vpp_service.frame import Calibration, StereoFrame

#: Nominal calibration of scikit-image's quarter-size Motorcycle (see the module docstring).
MOTORCYCLE_CALIB = Calibration(f=3979.911 / 4, baseline=0.193001, doffs=124.343 / 4)


@functools.lru_cache(maxsize=1)
def motorcycle_arrays() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read-only ``(left, right, disparity)``: H x W x 3 uint8 RGB, H x W float32 with NaN = invalid.

    Loaded once per process (scikit-image reads it from its data folder).
    """
    from skimage import data

    left, right, disp = data.stereo_motorcycle()
    disp = np.asarray(disp, dtype=np.float32).copy()
    disp[~np.isfinite(disp) | (disp <= 0)] = np.nan
    for a in (left, right, disp):
        a.setflags(write=False)
    return left, right, disp


def motorcycle() -> StereoFrame:
    """The Motorcycle pair with ground truth and :data:`MOTORCYCLE_CALIB`, named ``"motorcycle"``."""
    left, right, disp = motorcycle_arrays()
    return StereoFrame(left=left, right=right, calib=MOTORCYCLE_CALIB, gt_disparity=disp, name="motorcycle")


__all__ = ["MOTORCYCLE_CALIB", "motorcycle", "motorcycle_arrays"]
