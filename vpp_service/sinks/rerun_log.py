"""What the Rerun sink logs and how it looks: entities, archetypes, the default blueprint.

Shared by the ``rerun`` sink (one :class:`RerunParts` per fused frame) and by
``vpp-service view`` (one :class:`RerunParts` per received output message, each
with only the fields that message carries): both log through :class:`RerunLayout`.

Entities (root = the rig's name)
--------------------------------
``<rig>/left``, ``<rig>/right``
    The painted pair (the raw pair when VPP was off), JPEG-compressed
    (``rr.EncodedImage``) unless ``jpeg_quality`` is 0.
``<rig>/left/sparse``
    Sparse input points over the left image: small (1 UI point), coloured with
    the disparity colour map, at most ``max_sparse_points``; a separate entity,
    so the viewer's eye icon hides them.
``<rig>/disparity``
    Dense disparity as data, ``rr.DepthImage`` (values in pixels on hover,
    0 = invalid) with the ``turbo`` colour map over a fixed ``disparity_range``.
``<rig>/confidence``
    When logged (the sink's ``confidence``): the per-pixel confidence of the
    disparity as ``rr.DepthImage`` (values 0..1 on hover, 0 = no answer) with the
    ``viridis`` colour map over ``[0, 1]``.
``<rig>/camera`` and ``<rig>/camera/depth``
    ``rr.Pinhole`` at the origin of the 3-D view and the metric depth as
    ``rr.DepthImage`` (``meter = 1``), decimated to ``max_points`` pixels: the viewer
    back-projects it into the dense point cloud. Depths beyond ``depth_range``
    are left out so that the view's bounds are the scene's.
``<rig>/points``
    With ``points``: the point cloud as ``rr.Points3D`` in the left camera's frame
    (x right, y down, z forward, metres; the pinhole at ``<rig>/camera`` has no
    transform of its own, so ``<rig>`` is that frame and the points line up with the
    camera and its depth image), coloured from the (unpainted) left image: the valid,
    depth-clipped pixels on every ``points_stride``-th row and column, back-projected
    by :mod:`vpp_service.transport.backproject`. Not under ``<rig>/camera``: entities
    below a pinhole live in its 2-D image plane.
``<rig>/timing/<stage>``
    Per-stage milliseconds as scalars.
``<rig>/accuracy/<name>``
    When the frame carries ground truth: ``bad2_answered``, ``density`` and
    ``bad2_filled`` (percent; :mod:`vpp_service.metrics`) as scalars.

Colour ranges are fixed per recording: given, or taken once from the first frame
(robust percentiles) and then kept, so colours never jump between frames.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import cv2
import numpy as np

from vpp_service.frame import Calibration, FusionResult
from vpp_service.sinks.colorize import colorize_disparity
from vpp_service.transport.backproject import DEFAULT_STRIDE, depth_to_points
from vpp_service.transport.wire import sparse_to_points

if TYPE_CHECKING:
    import rerun as rr
    import rerun.blueprint as rrb

#: Allowed entity path parts (rig names, timing stages).
ENTITY_RE = re.compile(r"^[A-Za-z0-9_\-.]+$")


@dataclass
class RerunParts:
    """The loggable pieces of one frame; every field but the header is optional.

    Attributes
    ----------
    rig, seq, stamp_ns
        Header: entity root, ``seq`` timeline, ``stamp`` timeline (0 = none).
    left, right : ndarray or None
        The pair to show (painted or raw), H x W or H x W x 3 uint8 RGB.
    disparity : ndarray or None
        Dense float disparity in pixels (NaN / <= 0 = invalid).
    depth : ndarray or None
        Dense metric depth; computed from ``disparity`` and ``calib`` when absent.
    calib : Calibration or None
        Needed for the 3-D view.
    sparse : ndarray or None
        N x 3 float32 rows ``(x, y, disparity)`` (pixel indices).
    colors : ndarray or None
        The image the 3-D points are coloured from (the unpainted left image); None = grey.
    confidence : ndarray or None
        H x W float32 confidence of the disparity in [0, 1] (0 = no answer).
    timing_ms : dict
        Stage name -> milliseconds.
    accuracy : dict
        The reported accuracy numbers against ground truth (empty without it).
    """

    rig: str
    seq: int
    stamp_ns: int = 0
    left: np.ndarray | None = None
    right: np.ndarray | None = None
    disparity: np.ndarray | None = None
    depth: np.ndarray | None = None
    calib: Calibration | None = None
    sparse: np.ndarray | None = None
    colors: np.ndarray | None = None
    confidence: np.ndarray | None = None
    timing_ms: dict[str, float] = field(default_factory=dict)
    accuracy: dict[str, float] = field(default_factory=dict)


#: The accuracy numbers logged under ``<rig>/accuracy/`` (the three every report shows).
ACCURACY_KEYS = ("bad2_answered", "density", "bad2_filled")


def parts_from_result(result: FusionResult, log_painted: bool = True) -> RerunParts:
    """The :class:`RerunParts` of one fused result (the painted pair when present and wanted)."""
    fr = result.frame
    painted = log_painted and result.left_vpp is not None and result.right_vpp is not None
    return RerunParts(
        rig=fr.rig,
        seq=int(fr.seq),
        stamp_ns=int(fr.stamp_ns),
        left=result.left_vpp if painted else fr.left,
        right=result.right_vpp if painted else fr.right,
        disparity=np.asarray(result.disparity, dtype=np.float32),
        depth=result.depth,
        calib=fr.calib,
        sparse=sparse_to_points(fr.sparse_disparity),
        colors=fr.left,
        confidence=result.confidence,
        timing_ms=dict(result.timing_ms),
        accuracy={k: float(result.metrics[k]) for k in ACCURACY_KEYS if k in result.metrics},
    )


def depth_stride(height: int, width: int, max_points: int) -> int:
    """Smallest integer stride ``s`` with ``ceil(H/s) * ceil(W/s) <= max_points``.

    Parameters
    ----------
    height, width : int
        Image size (> 0).
    max_points : int
        Pixel budget (>= 1).

    Returns
    -------
    int
        Stride >= 1.

    Raises
    ------
    ValueError
        On non-positive arguments.
    """
    for name, v in (("height", height), ("width", width), ("max_points", max_points)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            raise ValueError(f"{name}: must be an integer >= 1, got {v!r}")
    s = max(1, math.floor(math.sqrt(height * width / max_points)))
    while math.ceil(height / s) * math.ceil(width / s) > max_points:
        s += 1
    return s


def robust_range(values: np.ndarray) -> tuple[float, float] | None:
    """``(1st, 99th)`` percentile of the finite, positive values (None when there are none)."""
    v = values[np.isfinite(values) & (values > 0)]
    if not v.size:
        return None
    lo, hi = (float(x) for x in np.percentile(v, [1.0, 99.0]))
    return (lo, hi) if hi > lo else (lo, lo + 1.0)


def _valid_map(a: np.ndarray) -> np.ndarray:
    """Float32 copy with NaN/inf/<= 0 set to 0 (Rerun's "no value" for depth images)."""
    out = np.array(a, dtype=np.float32, copy=True)
    out[~(np.isfinite(out) & (out > 0))] = 0.0
    return out


@dataclass
class RerunLayout:
    """Logs :class:`RerunParts` into a recording stream (see the module docstring).

    Attributes
    ----------
    jpeg_quality : int
        JPEG quality of the pair (1..100); 0 = uncompressed ``rr.Image``.
    disparity_range, depth_range : tuple of float or None
        Fixed colour ranges; None = taken from the first frame, then kept.
    max_points : int
        Pixel budget of the 3-D depth image.
    max_sparse_points : int
        Most sparse points logged per frame (evenly subsampled); 0 = none.
    point_cloud : bool
        Log the pinhole and the depth image.
    points : bool
        Log the pinhole and the point cloud as ``rr.Points3D`` (``<rig>/points``).
    points_stride : int
        Every ``points_stride``-th row and column of the depth map becomes a point.
    confidence : bool
        The blueprint shows ``<rig>/confidence`` beside the disparity.
    """

    jpeg_quality: int = 85
    disparity_range: tuple[float, float] | None = None
    depth_range: tuple[float, float] | None = None
    max_points: int = 200_000
    max_sparse_points: int = 5000
    point_cloud: bool = True
    points: bool = False
    points_stride: int = DEFAULT_STRIDE
    confidence: bool = False

    def blueprint(self, rig: str) -> rrb.Blueprint:
        """The default layout: the pair on top; disparity, 3-D and timing below."""
        import rerun.blueprint as rrb

        r = f"/{rig}"
        eye = None
        if self.depth_range is not None:
            # open on the scene: behind and slightly above the camera (RDF: -y is up), looking at its middle
            mid = 0.5 * (self.depth_range[0] + self.depth_range[1])
            eye = rrb.EyeControls3D(
                kind=rrb.Eye3DKind.Orbital,
                position=(0.0, -0.25 * mid, -0.5 * mid),
                look_target=(0.0, 0.0, mid),
                eye_up=(0.0, -1.0, 0.0),
            )
        disparity: rrb.Container | rrb.View = rrb.Spatial2DView(origin=f"{r}/disparity", name="disparity [px]")
        if self.confidence:
            disparity = rrb.Vertical(disparity, rrb.Spatial2DView(origin=f"{r}/confidence", name="confidence"))
        return rrb.Blueprint(
            rrb.Vertical(
                rrb.Horizontal(
                    rrb.Spatial2DView(origin=f"{r}/left", name="left (painted) + sparse points"),
                    rrb.Spatial2DView(origin=f"{r}/right", name="right (painted)"),
                ),
                rrb.Horizontal(
                    disparity,
                    rrb.Spatial3DView(
                        origin=r, contents=[f"{r}/camera/**", f"{r}/points"], name="3-D", eye_controls=eye
                    ),
                    rrb.Vertical(
                        rrb.TimeSeriesView(origin=f"{r}/timing", name="timing [ms]"),
                        rrb.TimeSeriesView(origin=f"{r}/accuracy", name="accuracy vs GT [%]"),
                    ),
                    column_shares=[2, 2, 1],
                ),
            ),
            collapse_panels=True,
        )

    def log_static(self, rec: rr.RecordingStream, rig: str) -> None:
        """Static data of a new recording (or a new file after rotation): the 3-D axes convention."""
        import rerun as rr

        rec.log(f"{rig}", rr.ViewCoordinates.RDF, static=True)

    def fix_ranges(self, parts: RerunParts) -> bool:
        """Take the missing colour ranges from ``parts``; True when one was set now."""
        changed = False
        if self.disparity_range is None and parts.disparity is not None:
            self.disparity_range = robust_range(parts.disparity)
            changed = self.disparity_range is not None
        if self.depth_range is None and self.point_cloud:
            depth = self._depth(parts)
            if depth is not None:
                self.depth_range = robust_range(depth)
                changed = changed or self.depth_range is not None
        return changed

    @staticmethod
    def _depth(parts: RerunParts) -> np.ndarray | None:
        if parts.depth is not None:
            return np.asarray(parts.depth, dtype=np.float32)
        if parts.disparity is None or parts.calib is None:
            return None
        c = parts.calib
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.float32(c.f * c.baseline) / (parts.disparity.astype(np.float32) + np.float32(c.doffs))

    def _image(self, img: np.ndarray) -> rr.Image | rr.EncodedImage:
        import rerun as rr

        if not self.jpeg_quality:
            return rr.Image(img)
        bgr = img[..., ::-1] if img.ndim == 3 else img
        ok, buf = cv2.imencode(".jpg", np.ascontiguousarray(bgr), [cv2.IMWRITE_JPEG_QUALITY, self.jpeg_quality])
        if not ok:
            raise ValueError("cannot JPEG-encode the image")
        return rr.EncodedImage(contents=buf.tobytes(), media_type="image/jpeg")

    def log(self, rec: rr.RecordingStream, parts: RerunParts) -> None:
        """Log every present piece of ``parts`` at its ``seq`` / ``stamp`` time."""
        import rerun as rr

        root = parts.rig
        rec.set_time("seq", sequence=int(parts.seq))
        if parts.stamp_ns:
            rec.set_time("stamp", timestamp=np.datetime64(int(parts.stamp_ns), "ns"))
        self.fix_ranges(parts)
        if parts.left is not None:
            rec.log(f"{root}/left", self._image(parts.left))
        if parts.right is not None:
            rec.log(f"{root}/right", self._image(parts.right))
        drng = self.disparity_range or (0.0, 1.0)
        if parts.disparity is not None:
            rec.log(
                f"{root}/disparity",
                rr.DepthImage(_valid_map(parts.disparity), meter=1.0, colormap="turbo", depth_range=drng),
            )
        if parts.confidence is not None:
            conf = np.asarray(parts.confidence, dtype=np.float32)
            rec.log(f"{root}/confidence", rr.DepthImage(conf, meter=1.0, colormap="viridis", depth_range=(0.0, 1.0)))
        if parts.sparse is not None and self.max_sparse_points:
            pts = parts.sparse
            if len(pts) > self.max_sparse_points:
                pts = pts[np.linspace(0, len(pts) - 1, self.max_sparse_points).astype(np.int64)]
            rec.log(
                f"{root}/left/sparse",
                rr.Points2D(
                    pts[:, :2] + np.float32(0.5),
                    colors=colorize_disparity(pts[:, 2], *drng),
                    radii=rr.Radius.ui_points(1.0),
                ),
            )
        if (self.point_cloud or self.points) and parts.calib is not None:
            depth = self._depth(parts)
            if depth is not None:
                self._log_depth(rec, root, depth, parts.calib)
                if self.points:
                    self._log_points(rec, root, depth, parts.calib, parts.colors)
        for group, values in (("timing", parts.timing_ms), ("accuracy", parts.accuracy)):
            for name, v in values.items():
                if isinstance(v, (int, float)) and math.isfinite(v) and ENTITY_RE.match(str(name)):
                    rec.log(f"{root}/{group}/{name}", rr.Scalars(float(v)))

    def _log_depth(self, rec: rr.RecordingStream, root: str, depth: np.ndarray, c: Calibration) -> None:
        import rerun as rr

        h, w = depth.shape
        s = depth_stride(h, w, self.max_points) if self.point_cloud else 1
        dd = _valid_map(depth[::s, ::s])
        if self.depth_range is not None:
            dd[dd > self.depth_range[1]] = 0.0  # far outliers would push the 3-D view's bounds away
        # OpenCV convention (pixel centres at integers) for cx, cy; Rerun puts
        # pixel centres at +0.5, and decimated pixel i is original pixel s*i.
        cx = (w - 1) / 2.0 if c.cx is None else float(c.cx)
        cy = (h - 1) / 2.0 if c.cy is None else float(c.cy)
        rec.log(
            f"{root}/camera",
            rr.Pinhole(
                focal_length=float(c.f) / s,
                principal_point=[cx / s + 0.5, cy / s + 0.5],
                width=dd.shape[1],
                height=dd.shape[0],
                camera_xyz=rr.ViewCoordinates.RDF,
            ),
        )
        if self.point_cloud:
            rec.log(
                f"{root}/camera/depth", rr.DepthImage(dd, meter=1.0, colormap="turbo", depth_range=self.depth_range)
            )

    def _log_points(
        self, rec: rr.RecordingStream, root: str, depth: np.ndarray, c: Calibration, colors: np.ndarray | None
    ) -> None:
        import rerun as rr

        image = colors if colors is not None and colors.shape[:2] == depth.shape else None
        xyz, rgb = depth_to_points(depth, image, c, stride=self.points_stride)
        rec.log(f"{root}/points", rr.Points3D(xyz, colors=rgb, radii=rr.Radius.ui_points(1.0)))


__all__ = [
    "ENTITY_RE",
    "RerunLayout",
    "RerunParts",
    "depth_stride",
    "parts_from_result",
    "robust_range",
]
