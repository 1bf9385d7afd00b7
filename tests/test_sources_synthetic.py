"""Synthetic scenes: exact, view-consistent ground truth and occlusions."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from vpp_service.frame import StereoFrame
from vpp_service.sources.synthetic import make_scene


def warp_abs_diff(frame: StereoFrame, disp: np.ndarray) -> np.ndarray:
    h, w = disp.shape
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    warped = cv2.remap(frame.right.astype(np.float32), xs - disp.astype(np.float32), ys, cv2.INTER_LINEAR)
    return np.abs(warped - frame.left.astype(np.float32)).mean(-1)


@pytest.mark.parametrize("kind", ["planes", "boxes"])
@pytest.mark.parametrize("texture", ["random", "weak"])
def test_scene_smoke(kind, texture):
    f = make_scene(120, 160, seed=3, kind=kind, texture=texture, max_disparity=24)
    assert f.left.shape == f.right.shape == (120, 160, 3) and f.left.dtype == np.uint8
    assert f.gt_disparity.dtype == np.float32 and f.gt_disparity.shape == (120, 160)
    assert np.isfinite(f.gt_disparity).all()
    assert f.gt_disparity.min() > 0 and f.gt_disparity.max() <= 24 + 1e-4
    assert f.nocc_mask.dtype == bool and 0.6 < f.nocc_mask.mean() < 1.0
    assert f.calib is not None and f.name == f"synthetic-{kind}-3" and f.meta["dataset"] == "synthetic"


@pytest.mark.parametrize(("kind", "seed"), [("planes", 0), ("planes", 5), ("boxes", 1)])
def test_gt_consistent_with_right_view(kind, seed):
    """Warping right to left by the GT matches at non-occluded pixels, and not by a shifted GT."""
    f = make_scene(seed=seed, kind=kind)
    _, w = f.shape
    xs = np.arange(w)[None, :]
    m = f.nocc_mask & (xs - f.gt_disparity >= 1)
    err = warp_abs_diff(f, f.gt_disparity)
    assert err[m].mean() < 3.0 and np.median(err[m]) < 2.0
    assert warp_abs_diff(f, f.gt_disparity + 2)[m].mean() > 4 * err[m].mean()
    # occluded pixels really are occluded: the right view shows something else there
    occ = ~f.nocc_mask & (xs - f.gt_disparity >= 1)
    assert occ.sum() > 50 and err[occ].mean() > 5 * err[m].mean()


def test_boxes_are_fronto_parallel_and_planes_slanted():
    boxes = make_scene(seed=2, kind="boxes", n_objects=3)
    planes = make_scene(seed=2, kind="planes", n_objects=3)
    # background rows are affine; box disparities take few distinct values beyond the background's
    gx_b = np.abs(np.diff(boxes.gt_disparity, axis=1))
    gx_p = np.abs(np.diff(planes.gt_disparity, axis=1))
    fg_b = boxes.gt_disparity > 0.45 * 48
    fg_p = planes.gt_disparity > 0.45 * 48
    assert np.median(gx_b[fg_b[:, 1:] & fg_b[:, :-1]]) < 1e-4
    assert np.median(gx_p[fg_p[:, 1:] & fg_p[:, :-1]]) > 1e-3


def test_weak_texture_has_low_contrast():
    strong = make_scene(seed=4, texture="random")
    weak = make_scene(seed=4, texture="weak")

    def lap(img):
        return np.abs(cv2.Laplacian(img.mean(-1).astype(np.float32), cv2.CV_32F)).mean()

    assert lap(weak.left) < 0.15 * lap(strong.left)
    np.testing.assert_array_equal(weak.gt_disparity, strong.gt_disparity)  # same layout


def test_seed_determinism_and_noise():
    a, b, c = make_scene(seed=9), make_scene(seed=9), make_scene(seed=10)
    np.testing.assert_array_equal(a.left, b.left)
    np.testing.assert_array_equal(a.gt_disparity, b.gt_disparity)
    assert not np.array_equal(a.gt_disparity, c.gt_disparity)
    noisy = make_scene(seed=9, noise=4.0)
    diff = noisy.left.astype(float) - a.left
    assert diff.std() == pytest.approx(4.0, rel=0.1)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"height": 8}, "height"),
        ({"width": 20.5}, "width"),
        ({"kind": "spheres"}, "kind"),
        ({"texture": "none"}, "texture"),
        ({"max_disparity": 200}, "max_disparity"),
        ({"seed": -1}, "seed"),
        ({"noise": -1.0}, "noise"),
        ({"n_objects": -2}, "n_objects"),
    ],
)
def test_errors(kwargs, match):
    with pytest.raises(ValueError, match=match):
        make_scene(**kwargs)
