"""Simulator source: a scene with ground truth plus a simulated sparse depth sensor.

The default source of ``vpp-service run``. Scenes:

- ``motorcycle`` (default): Middlebury 2014 *Motorcycle* as shipped by
  scikit-image (``skimage.data.stereo_motorcycle()``, 741 x 500, the left
  view's disparity with +inf = invalid, turned into NaN). scikit-image ships no
  calibration, so a nominal one is used: Middlebury's own ``calib.txt`` for
  Motorcycle scaled to this quarter resolution (:data:`MOTORCYCLE_CALIB`:
  f = 3979.911 / 4 px, baseline = 0.193 m, doffs = 124.343 / 4 px). Depths
  derived from it are plausible, not measured.
- ``synthetic``: :func:`vpp_service.sources.synthetic.make_scene` (options in ``scene_options``).
- ``dataset``: the ground truth of a dataset read with
  :func:`vpp_service.datasets.open_dataset` (``dataset``, ``root``), frames in turn.

Every frame gets a new ``seq`` (0, 1, ...), a wall-clock ``stamp_ns`` and a fresh
simulated sensor draw (seed = ``seed + seq``) from
:func:`vpp_service.sources.sensors.build_sensor` (``uniform`` 5 % by default).
Frames are paced at ``rate_hz`` (0 = as fast as possible); ``count = 0`` runs forever.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal

import cv2
import numpy as np

from vpp_service.datasets.skimage_scene import MOTORCYCLE_CALIB, motorcycle, motorcycle_arrays
from vpp_service.frame import Calibration, StereoFrame
from vpp_service.settings import OptionError, Options, Range, reject
from vpp_service.sources.base import SOURCES, Emit, Pacer, Reject, Source, SourceContext

if TYPE_CHECKING:
    from collections.abc import Mapping

    from vpp_service.datasets.base import Dataset
    from vpp_service.sources.sensors import NominalGeometry, Sensor


#: Size of the ``synthetic`` scene unless ``scene_options`` set ``height`` / ``width``.
SYNTHETIC_SIZE: dict[str, object] = {"height": 240, "width": 320}


def scaled_size(height: int, width: int, scale: float) -> tuple[int, int]:
    """``(height, width)`` of a frame of this size after :func:`scale_frame` by ``scale`` (at least 8 x 8)."""
    return (height, width) if scale == 1 else (max(8, round(height * scale)), max(8, round(width * scale)))


def _scale_points(sparse: np.ndarray, size: tuple[int, int], sx: float, sy: float, nearest: str) -> np.ndarray:
    """Move the points of a sparse map (NaN or <= 0 = none) onto a resized grid, values unchanged.

    Where several land on one pixel the nearest wins: the largest value
    (``nearest = "max"``, disparity) or the smallest (``"min"``, depth).
    """
    ys, xs = np.nonzero(np.isfinite(sparse) & (sparse > 0))
    w, h = size
    u = np.clip(np.floor((xs + 0.5) * sx).astype(np.int64), 0, w - 1)
    v = np.clip(np.floor((ys + 0.5) * sy).astype(np.int64), 0, h - 1)
    fill = -np.inf if nearest == "max" else np.inf
    out = np.full((h, w), fill, np.float32)
    (np.maximum if nearest == "max" else np.minimum).at(out, (v, u), sparse[ys, xs].astype(np.float32))
    out[~np.isfinite(out)] = np.nan
    return out


def scale_frame(frame: StereoFrame, scale: float) -> StereoFrame:
    """Resize a frame (images, ground truth, sparse depth, calibration) by ``scale`` in (0, 1].

    Disparities scale with the image width; ground truth is resampled with
    nearest neighbour (no mixing across depth edges); each sparse point moves
    to the pixel its position falls in (the nearest wins a pixel), metric
    ``sensor_depth`` keeps its values.

    Raises
    ------
    ValueError
        ``scale`` outside (0, 1].
    """
    if not 0 < scale <= 1:
        raise ValueError(f"scale must be in (0, 1], got {scale!r}")
    if scale == 1:
        return frame
    h, w = frame.shape
    sh, sw = scaled_size(h, w, scale)
    size = (sw, sh)
    sx = size[0] / w
    left = cv2.resize(frame.left, size, interpolation=cv2.INTER_AREA)
    right = cv2.resize(frame.right, size, interpolation=cv2.INTER_AREA)
    gt = None
    if frame.gt_disparity is not None:
        gt = cv2.resize(frame.gt_disparity, size, interpolation=cv2.INTER_NEAREST) * np.float32(sx)
    calib = frame.calib
    if calib is not None:
        calib = Calibration(
            f=calib.f * sx,
            baseline=calib.baseline,
            doffs=calib.doffs * sx,
            cx=None if calib.cx is None else calib.cx * sx,
            cy=None if calib.cy is None else calib.cy * sx,
        )
    nocc = None
    if frame.nocc_mask is not None:
        nocc = cv2.resize(frame.nocc_mask.astype(np.uint8), size, interpolation=cv2.INTER_NEAREST).astype(bool)
    sy = size[1] / h
    sparse = None
    if frame.sparse_disparity is not None:
        sparse = _scale_points(frame.sparse_disparity, size, sx, sy, "max") * np.float32(sx)
    depth = None if frame.sensor_depth is None else _scale_points(frame.sensor_depth, size, sx, sy, "min")
    return frame.with_(
        left=left,
        right=right,
        gt_disparity=gt,
        calib=calib,
        nocc_mask=nocc,
        sparse_disparity=sparse,
        sensor_depth=depth,
    )


def motorcycle_frame(scale: float = 1.0) -> StereoFrame:
    """The scikit-image Motorcycle pair as a :class:`StereoFrame` with ground truth.

    Parameters
    ----------
    scale : float
        Resize factor in (0, 1] (disparities and calibration scale with it).
    """
    frame = motorcycle()
    return scale_frame(frame, scale)


@dataclass(frozen=True)
class SimSourceOptions(Options):
    """Options of the ``sim`` source.

    Attributes
    ----------
    scene : {"motorcycle", "synthetic", "dataset"}
        What to simulate (see the module docstring).
    scene_options : dict
        Keyword arguments of ``make_scene`` (synthetic scene).
    dataset, root : str
        Dataset name (or "auto") and folder for ``scene = "dataset"``.
    scale : float
        Resize factor in (0, 1] applied to every frame.
    sensor : str
        Sensor simulator name (``uniform``, ``lidar``, ``tof``) or ``"none"``.
    sensor_options : dict
        Options of the sensor simulator (e.g. ``{density = 0.05}``).
    rate_hz : float
        Frame rate; 0 = as fast as possible.
    count : int
        Frames to produce; 0 = forever.
    seed : int
        Base seed; frame ``seq`` uses ``seed + seq``.
    """

    scene: Literal["motorcycle", "synthetic", "dataset"] = "motorcycle"
    scene_options: dict[str, Any] = field(default_factory=dict)
    dataset: str = "auto"
    root: str = ""
    scale: Annotated[float, Range(0.0, 1.0, lo_open=True)] = 1.0
    sensor: str = "uniform"
    sensor_options: dict[str, object] = field(default_factory=lambda: {"density": 0.05})
    rate_hz: Annotated[float, Range(0.0, 10000.0)] = 10.0
    count: Annotated[int, Range(0)] = 0
    seed: int = 0

    def cross_check(self) -> None:
        """A dataset scene names its folder."""
        if self.scene == "dataset" and not self.root:
            raise reject("root", self.root, "a dataset folder when scene = 'dataset'")


def check_sensor_input(dataset: str, root: str, sensor: str, section: str, *, own_sparse: bool) -> None:
    """Fail early when a dataset replay would need ground truth its folder lacks.

    A simulated ``sensor`` (anything but ``"none"``) draws each frame's sparse
    depth from its ground truth. With ``own_sparse`` (the ``files`` source),
    frames that carry their own sparse depth (the ``folder`` layout's
    ``sparse/``) need none. Opening the dataset here also reports a folder that
    matches no layout. A folder of ``*.msgpack`` frames (``dataset = "auto"``)
    is left to the source.

    Raises
    ------
    ValueError
        ``<section>.root: <folder> has no ground truth ...``, in one line; or the
        dataset reader's own error (no layout matched, mismatched files).
    """
    from vpp_service.datasets import open_dataset

    try:
        ds = open_dataset(dataset, Path(root).expanduser())
    except ValueError:
        if dataset == "auto" and any(Path(root).expanduser().glob("*.msgpack")):
            return  # a recording: replayed as wire frames
        raise
    if sensor == "none" or ds.has_ground_truth or (own_sparse and ds.has_sparse_input):
        return
    how = (
        "add your sparse depth as sparse/<frame>.png|.npy|.csv|.txt (docs/deployment.md, 'Your own recordings')"
        if own_sparse
        else 'the sim source always simulates: use type = "files" with your sparse depth in sparse/'
    )
    raise ValueError(
        f"{section}.root: {root} has no ground truth (disp/) for the simulated sensor {sensor!r} to draw "
        f'sparse depth from; {how}, or set {section}.sensor = "none"'
    )


def build_sensor_or_none(name: str, options: Mapping[str, object]) -> Sensor[NominalGeometry] | None:
    """The named sensor simulator, or None for ``"none"``."""
    if name == "none":
        return None
    from vpp_service.sources.sensors import build_sensor

    return build_sensor(name, options)


@SOURCES.register("sim")
class SimSource(Source):
    """Simulated camera rig (see the module docstring)."""

    Options = SimSourceOptions
    options: SimSourceOptions

    @classmethod
    def check_options(cls, options: SimSourceOptions, section: str) -> None:
        """Build the sensor once, so a bad ``sensor`` / ``sensor_options`` fails the config check.

        Raises
        ------
        OptionError
            ``<section>.sensor: ...`` (unknown sensor) or ``<section>.sensor_options.<key>: ...``.
        """
        from vpp_service.sources.sensors import SENSORS

        if options.sensor != "none" and options.sensor not in SENSORS:
            known = ", ".join(repr(n) for n in [*SENSORS.names(), "none"])
            raise OptionError(f"{section}.sensor", repr(options.sensor), f"one of {known}")
        try:
            build_sensor_or_none(options.sensor, dict(options.sensor_options))
        except OptionError as exc:  # name the key under this section, not the sensor's own
            key = exc.key.removeprefix(f"sensor.{options.sensor}.")
            raise OptionError(f"{section}.sensor_options.{key}", exc.got, exc.expected) from None

    @classmethod
    def check_paths(cls, options: SimSourceOptions, section: str, created_dirs: frozenset[Path] = frozenset()) -> None:
        """``scene = "dataset"``: ``root`` must be an existing dataset folder with ground truth for the sensor."""
        if options.scene != "dataset":
            return
        if not Path(options.root).expanduser().is_dir():
            raise FileNotFoundError(f"{section}.root: no such folder: {options.root}")
        check_sensor_input(options.dataset, options.root, options.sensor, section, own_sparse=False)

    @classmethod
    def frame_size(cls, options: SimSourceOptions) -> tuple[int, int] | None:
        """The scene's size after ``scale``: Motorcycle's, or the synthetic scene's; None for a dataset."""
        if options.scene == "motorcycle":
            left = motorcycle_arrays()[0]
            return scaled_size(left.shape[0], left.shape[1], options.scale)
        if options.scene == "synthetic":
            opts = {**SYNTHETIC_SIZE, **dict(options.scene_options)}
            h, w = opts["height"], opts["width"]
            if isinstance(h, int) and isinstance(w, int) and not isinstance(h, bool) and not isinstance(w, bool):
                return scaled_size(h, w, options.scale)
        return None

    def __init__(self, options: SimSourceOptions, context: SourceContext) -> None:
        super().__init__(options, context)
        self._scenes: list[StereoFrame] | None = None
        self._dataset: Dataset | None = None
        self.sensor: Sensor[NominalGeometry] | None = None

    def open(self) -> None:
        """Load the scene and build the sensor (fails early on bad options)."""
        o = self.options
        self.sensor = build_sensor_or_none(o.sensor, dict(o.sensor_options))
        if o.scene == "motorcycle":
            self._scenes = [motorcycle_frame(o.scale)]
        elif o.scene == "synthetic":
            from vpp_service.sources.synthetic import make_scene

            opts = {**SYNTHETIC_SIZE, **dict(o.scene_options)}
            self._scenes = [scale_frame(make_scene(seed=o.seed, **opts), o.scale)]
        else:
            from vpp_service.datasets import open_dataset

            self._dataset = open_dataset(o.dataset, o.root)
            if len(self._dataset) == 0:
                raise ValueError(f"source.root: no frames in dataset {o.dataset!r} at {o.root}")

    def frame(self, seq: int) -> StereoFrame:
        """Frame number ``seq`` (scene, sensor draw, identity), without pacing."""
        o = self.options
        if self._scenes is not None:
            base = self._scenes[seq % len(self._scenes)]
        elif self._dataset is not None:
            base = scale_frame(self._dataset[seq % len(self._dataset)], o.scale)
        else:
            raise RuntimeError("sim source: frame() before open()")
        base = base.with_(rig=self.context.rig, seq=seq, stamp_ns=time.time_ns(), meta=dict(base.meta))
        if self.sensor is not None:
            base = self.sensor.simulate(base, o.seed + seq)
        return base

    def run(self, emit: Emit, reject: Reject) -> None:
        """Emit frames at ``rate_hz`` until ``count`` or stopped."""
        pacer = Pacer(self.options.rate_hz)
        seq = 0
        while self.options.count == 0 or seq < self.options.count:
            if pacer.wait(self):
                return
            frame = self.frame(seq)
            self._counters["emitted"] += 1
            emit(frame)
            seq += 1


__all__ = [
    "MOTORCYCLE_CALIB",
    "SimSource",
    "SimSourceOptions",
    "check_sensor_input",
    "motorcycle_frame",
    "scale_frame",
    "scaled_size",
]
