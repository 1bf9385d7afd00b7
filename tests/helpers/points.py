"""Point-cloud outputs in tests: a depth-clipped fused result, and the check that a cloud is its depth map.

:func:`clipped_result` runs the real fusion step (SGBM on a synthetic scene) with a depth clip
narrower than the scene, so that some pixels are clipped; :func:`assert_cloud_is_depth` checks a
cloud read back from an output against the result's depth map by projecting every point back
into the image (the inverse of the back-projection, written out here independently of it).
"""

from __future__ import annotations

import numpy as np

from vpp_service.frame import Calibration, FusionResult
from vpp_service.fusion import fuse
from vpp_service.matchers import build_matcher
from vpp_service.matchers.depth_clip import DepthClip
from vpp_service.sources.synthetic import make_scene

#: The synthetic rig: f = 500 px, B = 0.1 m (f B = 50 m px), an off-centre principal point.
CALIB = Calibration(f=500.0, baseline=0.1, cx=70.25, cy=27.5)
#: The depth clip: disparities 11 .. 36 px, i.e. 1.39 .. 4.55 m; the scenes span about 9 .. 48 px.
NEAR_M, FAR_M = 50.0 / 36.0, 50.0 / 11.0


def clipped_result(seq: int = 3, rig: str = "r1") -> FusionResult:
    """A fused, depth-clipped result of a 64 x 128 synthetic RGB scene (plain SGBM, metric depth)."""
    scene = make_scene(64, 128, seed=seq, max_disparity=48, f=CALIB.f, baseline=CALIB.baseline)
    assert scene.left.ndim == 3  # RGB: the colours of the points are checked per channel
    frame = scene.with_(calib=CALIB, seq=seq, rig=rig, stamp_ns=1_000_000 + seq)
    matcher = build_matcher("sgbm", {"max_disparity": 64})
    return fuse(frame, matcher, None, depth=True, depth_clip=DepthClip(min_depth_m=NEAR_M, max_depth_m=FAR_M))


def assert_cloud_is_depth(
    xyz: np.ndarray, rgb: np.ndarray, result: FusionResult, stride: int, calib: Calibration = CALIB
) -> None:
    """``xyz`` / ``rgb`` hold exactly the valid pixels of ``result.depth`` on the ``stride`` grid.

    Each point projects back (``u = f x / z + cx``) onto a grid pixel whose depth is the
    point's ``z`` and whose left-image colour is the point's colour; every valid grid pixel
    has its point, and no point lies outside the depth clip.
    """
    depth = result.depth
    assert depth is not None
    assert xyz.dtype == np.float32 and xyz.shape[1] == 3 and rgb.dtype == np.uint8 and rgb.shape == xyz.shape
    z = xyz[:, 2].astype(np.float64)
    assert np.all(np.isfinite(xyz)) and np.all(z > 0)
    assert z.max() <= FAR_M * (1 + 1e-6) and z.min() >= NEAR_M * (1 - 1e-6), "a point outside the depth clip"
    u = xyz[:, 0] * calib.f / z + calib.cx
    v = xyz[:, 1] * calib.f / z + calib.cy
    ui, vi = np.rint(u).astype(np.int64), np.rint(v).astype(np.int64)
    np.testing.assert_allclose(u, ui, atol=1e-3)
    np.testing.assert_allclose(v, vi, atol=1e-3)
    assert np.all(ui % stride == 0) and np.all(vi % stride == 0), "a point off the stride grid"
    np.testing.assert_array_equal(xyz[:, 2], depth[vi, ui])
    np.testing.assert_array_equal(rgb, result.frame.left[vi, ui])
    grid = depth[::stride, ::stride]
    valid = np.isfinite(grid) & (grid > 0)
    assert len(xyz) == int(valid.sum()) == len({(a, b) for a, b in zip(vi.tolist(), ui.tolist(), strict=True)})
    assert 0.2 < valid.mean() < 0.9, "the clip should have removed part of the scene, not all of it"


def read_ply(data: bytes) -> tuple[list[str], np.ndarray]:
    """A binary little-endian PLY of x y z float / red green blue uchar vertices: (comments, records)."""
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode("ascii").splitlines()
    assert header[:2] == ["ply", "format binary_little_endian 1.0"]
    props = [line.split()[1:] for line in header if line.startswith("property ")]
    assert props == [
        ["float", "x"],
        ["float", "y"],
        ["float", "z"],
        ["uchar", "red"],
        ["uchar", "green"],
        ["uchar", "blue"],
    ]
    (n,) = (int(line.split()[2]) for line in header if line.startswith("element vertex "))
    dtype = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("r", "u1"), ("g", "u1"), ("b", "u1")])
    assert len(data) - end == n * dtype.itemsize  # 15 bytes a vertex, nothing after them
    return [line[8:] for line in header if line.startswith("comment ")], np.frombuffer(data[end:], dtype)
