"""The data types that flow through the project: calibration and stereo frames.

Dataset readers, the simulators, the streaming sources and the pipeline all
produce or consume :class:`StereoFrame`; keeping one type means a frame read
from disk, simulated, or decoded off Zenoh is handled by the same code.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np


@dataclass(frozen=True)
class Calibration:
    """Rectified stereo calibration.

    Parameters
    ----------
    f : float
        Focal length of the rectified left camera, pixels (> 0).
    baseline : float
        Distance between the optical centres, metres (> 0).
    doffs : float, optional
        Principal-point offset between the views (Middlebury), pixels.
        Disparity ``d = f * baseline / Z - doffs``. Default 0.
    cx, cy : float or None, optional
        Principal point of the left camera, pixels; ``None`` means the image
        centre (used only for 3-D visualisation).
    """

    f: float
    baseline: float
    doffs: float = 0.0
    cx: float | None = None
    cy: float | None = None

    def __post_init__(self) -> None:
        for name in ("f", "baseline"):
            v = getattr(self, name)
            if not isinstance(v, (int, float)) or not np.isfinite(v) or v <= 0:
                raise ValueError(f"calibration {name} must be a finite number > 0, got {v!r}")
        for name in ("doffs", "cx", "cy"):
            v = getattr(self, name)
            if v is not None and (not isinstance(v, (int, float)) or not np.isfinite(v)):
                raise ValueError(f"calibration {name} must be a finite number, got {v!r}")

    def to_dict(self) -> dict[str, float]:
        """Plain-dict form (the wire format's ``calib``)."""
        d = {"f": float(self.f), "baseline": float(self.baseline), "doffs": float(self.doffs)}
        if self.cx is not None:
            d["cx"] = float(self.cx)
        if self.cy is not None:
            d["cy"] = float(self.cy)
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Calibration:
        """Build from a dict with keys ``f``, ``baseline`` and optional ``doffs``, ``cx``, ``cy``."""
        if not isinstance(d, dict):
            raise ValueError(f"calibration must be a mapping, got {type(d).__name__}")
        missing = {"f", "baseline"} - set(d)
        if missing:
            raise ValueError(f"calibration is missing {sorted(missing)}")
        return cls(
            f=d["f"],
            baseline=d["baseline"],
            doffs=d.get("doffs", 0.0),
            cx=d.get("cx"),
            cy=d.get("cy"),
        )


@dataclass
class StereoFrame:
    """One rectified stereo frame with optional sparse depth and ground truth.

    Attributes
    ----------
    left, right : ndarray
        H x W or H x W x C uint8 images (C = 1 or 3, RGB order), same shape.
    calib : Calibration or None
        Needed to convert metric depth to disparity and back.
    sparse_disparity : ndarray or None
        H x W float32 sparse disparity registered to ``left`` (pixels);
        NaN or <= 0 = no point. This is what VPP consumes.
    sensor_depth : ndarray or None
        H x W float32 sparse metric depth registered to ``left`` (metres);
        0 or NaN = no point (e.g. a real LiDAR scan projected into the image).
    gt_disparity : ndarray or None
        H x W float32 ground-truth disparity of ``left``; NaN = invalid.
    nocc_mask : ndarray or None
        H x W bool, True where ground truth is not occluded.
    name : str
        Scene or dataset name (for reports).
    rig, seq, stamp_ns
        Stream identity: rig name, sequence number, capture time (ns).
    meta : dict
        Free-form extras (dataset path, ...). ``meta["lidar_like"] = True``
        declares that the sparse points come from a sensor mounted away from
        the left camera (a LiDAR scan), so some may see through foreground
        edges: the fusion step's ``auto`` depth filter then removes them
        (:mod:`vpp_service.vpp.see_through`). Set by the ``lidar`` simulator with a pose,
        the KITTI reader (Velodyne scans) and the ROS 2 sources (PointCloud2).
    """

    left: np.ndarray
    right: np.ndarray
    calib: Calibration | None = None
    sparse_disparity: np.ndarray | None = None
    sensor_depth: np.ndarray | None = None
    gt_disparity: np.ndarray | None = None
    nocc_mask: np.ndarray | None = None
    name: str = ""
    rig: str = "rig0"
    seq: int = 0
    stamp_ns: int = 0
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) of the frame."""
        return self.left.shape[:2]

    def with_(self, **changes: Any) -> StereoFrame:
        """A shallow copy with some fields replaced."""
        return replace(self, **changes)


@dataclass
class FusionResult:
    """What the pipeline produces for one frame and hands to every sink.

    Attributes
    ----------
    frame : StereoFrame
        The input frame (images, calibration, sparse points, ground truth if known).
    disparity : ndarray
        H x W float32 dense disparity of the left view; NaN = invalid.
    depth : ndarray or None
        H x W float32 metric depth (metres, NaN = invalid) when calibrated.
    confidence : ndarray or None
        H x W float32 per-pixel confidence of ``disparity`` in [0, 1], 0 where it is NaN
        (:meth:`Matcher.compute_with_confidence <vpp_service.matchers.base.Matcher.compute_with_confidence>`);
        None when nothing asked for it.
    left_vpp, right_vpp : ndarray or None
        The painted pair fed to the matcher (None when VPP was disabled).
    occluded : ndarray or None
        H x W bool, sparse points classified occluded by VPP.
    vpp_stats : dict
        VPP point counts of the frame, :meth:`VPPStats.to_dict <vpp_service.vpp.VPPStats.to_dict>`
        (``given``, ``projected``, ``occluded``, ``invalid``, ``out_of_bounds``); empty when VPP did not run.
    timing_ms : dict
        Per-stage wall time in milliseconds (e.g. decode, vpp, match, process).
    metrics : dict
        Accuracy vs ground truth when the frame has it (bad2, avg, ...).
    see_through : int or None
        Sparse points the see-through filter dropped before VPP
        (:mod:`vpp_service.vpp.see_through`); None when it did not run.
    """

    frame: StereoFrame
    disparity: np.ndarray
    depth: np.ndarray | None = None
    confidence: np.ndarray | None = None
    left_vpp: np.ndarray | None = None
    right_vpp: np.ndarray | None = None
    occluded: np.ndarray | None = None
    vpp_stats: dict[str, int] = field(default_factory=dict)
    timing_ms: dict[str, float] = field(default_factory=dict)
    metrics: dict[str, float] = field(default_factory=dict)
    see_through: int | None = None
