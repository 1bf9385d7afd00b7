"""Sparse depth-sensor simulators: ground-truth disparity -> what a sensor would measure.

None of the benchmark scenes ships a raw single-sweep scan, so the sparse input
of VPP is simulated from the ground truth. Every sensor returns a copy of the
frame with ``sparse_disparity`` (H x W float32, NaN = no point) and, when the
frame has a calibration, ``sensor_depth`` (metres, 0 = no point). Without a
calibration the metric models (range limits, range noise) use a nominal focal
length and baseline (options ``nominal_f``, ``nominal_baseline``).

Depth and disparity are related by ``Z = f * b / (d + doffs)``.

Sensors (``SENSORS.names()``):

* ``uniform`` - the paper's protocol: a point fraction ``density`` of the valid
  ground-truth pixels, drawn uniformly at random (seeded), values = ground
  truth plus optional Gaussian disparity noise ``noise_px``.
* ``lidar`` - a spinning multi-beam LiDAR: ``beams`` elevations evenly spread
  over ``[fov_down, fov_up]`` degrees and azimuths every ``azimuth_step``
  degrees; each ray hits the image at ``u = cx + f tan(az)``,
  ``v = cy - f tan(el) / cos(az)`` (so beams are slightly curved rows),
  measures the range there with Gaussian noise ``noise_m`` and drops returns
  outside ``[min_range, max_range]`` or with probability ``dropout``. By
  default the LiDAR sits at the left camera centre. ``pose`` (the LiDAR
  origin in the left camera frame, metres: x right, y down, z forward, or a
  preset name from :data:`LIDAR_POSES`) and ``rotation`` (degrees about the
  camera's x, y, z axes) mount it elsewhere: the beams are then cast from the
  LiDAR's own viewpoint against the ground-truth surface
  (:func:`~vpp_service.sources.lidar_view.render_lidar_depth`: a z-buffer of
  the surface, with the background hidden behind foreground edges) and the
  returns projected into the left camera (nearest wins a pixel), so returns
  the LiDAR sees past a foreground edge land on foreground pixels with
  background depth (*see-through points*), as on a real rig.
* ``tof`` - a low-resolution time-of-flight camera: a ``grid_w`` x ``grid_h``
  grid of cell centres over the image, depth noise ``sigma = noise_k * z**2``,
  returns beyond ``max_range`` (or below ``min_range``) lost, ``dropout``.

All randomness comes from ``numpy.random.default_rng(seed)``: the same frame and
seed give the same points.

Frames from the ``lidar`` sensor mounted away from the camera (a ``pose`` or
``rotation``) carry ``meta["lidar_like"] = True``: its points may see through
foreground edges, so the fusion step's ``auto`` depth filter removes
see-through points (:mod:`vpp_service.vpp.see_through`). At the camera centre,
and from ``uniform`` and ``tof`` (registered to the left view), ``False``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Annotated, ClassVar, Generic, TypeVar

import numpy as np

from vpp_service.frame import StereoFrame
from vpp_service.registry import Registry
from vpp_service.settings import Each, Options, Range, from_mapping, reject
from vpp_service.sources.lidar_view import render_lidar_depth, rotation_matrix
from vpp_service.vpp.see_through import LIDAR_LIKE

#: LiDAR poses by name: the LiDAR origin in the (rectified) left camera frame, metres (x right, y down,
#: z forward). ``kitti``: KITTI's raw-data calibration ``calib_velo_to_cam.txt`` (2011_09_26, the
#: Velodyne HDL-64E to camera 0: ``T = (-4.069766e-03, -7.631618e-02, -2.717806e-01)``) rotated by the
#: rectifying ``R_rect_00`` of ``calib_cam_to_cam.txt``: the Velodyne is 0.27 m behind and 0.075 m above
#: the left camera (Geiger et al., IJRR 2013, Fig. 3: 0.27 m, 1.73 - 1.65 = 0.08 m). The preset has no
#: rotation: the remaining 0.6 degree tilt of that calibration changes where beams fall, not what they see.
LIDAR_POSES: dict[str, tuple[float, float, float]] = {
    "zero": (0.0, 0.0, 0.0),
    "kitti": (-0.0028, -0.0751, -0.2721),
}

#: Sensor classes by name.
SENSORS: Registry[Sensor[NominalGeometry]] = Registry("sensor")


#: Markers of the sensors' options: a finite number > 0, >= 0, or a probability in [0, 1).
_POSITIVE = Range(0.0, lo_open=True)
_NON_NEGATIVE = Range(0.0)
_PROBABILITY = Range(0.0, 1.0, hi_open=True)


def _check_range(min_range: float, max_range: float) -> None:
    """Raise the OptionError of a ``max_range`` not beyond ``min_range``."""
    if max_range <= min_range:
        raise reject("max_range", max_range, f"> min_range ({min_range})")


@dataclass(frozen=True)
class NominalGeometry(Options):
    """Options every sensor shares: the geometry assumed for uncalibrated frames.

    Attributes
    ----------
    nominal_f : float
        Focal length (px) assumed when the frame has no calibration. Default 1000.
    nominal_baseline : float
        Baseline (m) assumed when the frame has no calibration. Default 0.1.
    """

    nominal_f: Annotated[float, _POSITIVE] = 1000.0
    nominal_baseline: Annotated[float, _POSITIVE] = 0.1


#: The options dataclass of one sensor class (covariant: a ``Sensor[LidarSensor.Options]`` is a
#: ``Sensor[NominalGeometry]``, since the options are read-only).
OptionsT_co = TypeVar("OptionsT_co", bound=NominalGeometry, covariant=True)


class Sensor(Generic[OptionsT_co]):
    """Base class: turns a frame's ground truth into sparse measurements.

    Each subclass sets ``Options`` (a frozen :class:`NominalGeometry` subclass)
    and ``name`` and implements :meth:`simulate`.

    Parameters
    ----------
    options : Options of the subclass or None
        Built by :func:`build_sensor` (validated); None means the defaults.
    """

    #: Frozen dataclass of the sensor's options; set by each subclass.
    Options: type[OptionsT_co]
    #: Registered name, written into ``frame.meta["sensor"]``.
    name: ClassVar[str] = ""

    def __init__(self, options: OptionsT_co | None = None) -> None:
        if options is None:
            options = self.Options()
        if not isinstance(options, self.Options):
            raise TypeError(f"options: must be a {self.Options.__name__}, got {type(options).__name__}")
        self._options = options

    @property
    def options(self) -> OptionsT_co:
        """The sensor's validated options."""
        return self._options

    def _geometry(self, frame: StereoFrame) -> tuple[float, float, float, float, float]:
        """(f, baseline, doffs, cx, cy) of the frame, nominal values when uncalibrated."""
        h, w = frame.shape
        c = frame.calib
        if c is None:
            return (self.options.nominal_f, self.options.nominal_baseline, 0.0, (w - 1) / 2.0, (h - 1) / 2.0)
        cx = c.cx if c.cx is not None else (w - 1) / 2.0
        cy = c.cy if c.cy is not None else (h - 1) / 2.0
        return (float(c.f), float(c.baseline), float(c.doffs), float(cx), float(cy))

    @staticmethod
    def _gt(frame: StereoFrame) -> np.ndarray:
        if not isinstance(frame, StereoFrame):
            raise TypeError(f"frame: must be a StereoFrame, got {type(frame).__name__}")
        gt = frame.gt_disparity
        if gt is None:
            raise ValueError(f"frame.gt_disparity: frame {frame.name!r} has no ground truth to simulate a sensor from")
        if not isinstance(gt, np.ndarray) or gt.shape != frame.shape:
            raise ValueError(f"frame.gt_disparity: must be an H x W array matching the images {frame.shape}")
        gt = gt.astype(np.float32, copy=False)
        return np.where(np.isfinite(gt) & (gt > 0), gt, np.nan).astype(np.float32)

    @classmethod
    def _begin(cls, frame: StereoFrame, seed: int) -> tuple[np.ndarray, np.random.Generator]:
        """Validated ground truth (NaN = invalid) and the seeded generator of one simulation."""
        gt = cls._gt(frame)
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ValueError(f"seed: must be an integer >= 0, got {seed!r}")
        return gt, np.random.default_rng(seed)

    @staticmethod
    def _true_depth(
        gt: np.ndarray, rows: np.ndarray, cols: np.ndarray, *, f: float, b: float, doffs: float
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Sample ``gt`` at (rows, cols); keep the valid hits, return them with their depth."""
        d = gt[rows, cols].astype(np.float64)
        hit = np.isfinite(d)
        return rows[hit], cols[hit], f * b / (d[hit] + doffs)

    @staticmethod
    def _measured_disparity(z_meas: np.ndarray, keep: np.ndarray, f: float, b: float, doffs: float) -> np.ndarray:
        """Disparity of measured depths (rows not kept get a placeholder, never read)."""
        return f * b / np.where(keep, z_meas, 1.0) - doffs

    def _output(
        self, frame: StereoFrame, rows: np.ndarray, cols: np.ndarray, disp: np.ndarray, *, depth: np.ndarray | None
    ) -> StereoFrame:
        """Assemble the sparse maps; drops non-positive disparities/depths."""
        h, w = frame.shape
        keep = np.isfinite(disp) & (disp > 0)
        if depth is not None:
            keep &= np.isfinite(depth) & (depth > 0)
        sparse = np.full((h, w), np.nan, np.float32)
        sparse[rows[keep], cols[keep]] = disp[keep]
        sensor_depth = None
        if frame.calib is not None:
            f, b, doffs, _, _ = self._geometry(frame)
            sensor_depth = np.zeros((h, w), np.float32)
            z = depth[keep] if depth is not None else f * b / (disp[keep] + doffs)
            sensor_depth[rows[keep], cols[keep]] = z
        meta = dict(frame.meta)
        meta["sensor"] = self.name
        meta[LIDAR_LIKE] = self.sees_past_edges()
        return frame.with_(sparse_disparity=sparse, sensor_depth=sensor_depth, meta=meta)

    def sees_past_edges(self) -> bool:
        """Whether the points may see past foreground edges (written into ``frame.meta["lidar_like"]``).

        False here: the sensor is registered to the left camera. The ``lidar``
        sensor mounted away from the camera overrides it.
        """
        return False

    def simulate(self, frame: StereoFrame, seed: int = 0) -> StereoFrame:
        """Simulate one measurement of ``frame`` (a copy; the input is unchanged).

        Parameters
        ----------
        frame : StereoFrame
            Must carry ``gt_disparity``.
        seed : int
            Seed of every random choice (>= 0).

        Returns
        -------
        StereoFrame
            Copy with ``sparse_disparity`` and (calibrated frames) ``sensor_depth``.
        """
        raise NotImplementedError


@SENSORS.register("uniform")
class UniformSensor(Sensor["UniformSensor.Options"]):
    """Uniform random sampling of valid ground-truth pixels (the paper's protocol)."""

    name = "uniform"

    @dataclass(frozen=True)
    class Options(NominalGeometry):
        """Options of the ``uniform`` sensor.

        Attributes
        ----------
        density : float
            Fraction of the *valid* ground-truth pixels sampled, in (0, 1]. Default 0.05.
        noise_px : float
            Std of Gaussian noise added to the sampled disparities (px). Default 0.
        nominal_f, nominal_baseline : float
            Used for ``sensor_depth`` only when the frame has no calibration (it is then not written).
        """

        density: Annotated[float, Range(0.0, 1.0, lo_open=True)] = 0.05
        noise_px: Annotated[float, _NON_NEGATIVE] = 0.0

    def simulate(self, frame: StereoFrame, seed: int = 0) -> StereoFrame:
        """Sample ``density`` of the valid ground-truth pixels (see :meth:`Sensor.simulate`)."""
        gt, rng = self._begin(frame, seed)
        valid = np.flatnonzero(np.isfinite(gt).ravel())
        n = round(self.options.density * valid.size)
        pick = np.sort(rng.choice(valid, size=n, replace=False)) if n else valid[:0]
        rows, cols = np.divmod(pick, frame.shape[1])
        disp = gt.ravel()[pick].astype(np.float64)
        if self.options.noise_px > 0:
            disp = disp + rng.normal(0.0, self.options.noise_px, size=disp.size)
        return self._output(frame, rows, cols, disp.astype(np.float32), depth=None)


@SENSORS.register("lidar")
class LidarSensor(Sensor["LidarSensor.Options"]):
    """Spinning multi-beam LiDAR at the left camera centre or mounted beside it (see module docs)."""

    name = "lidar"

    @dataclass(frozen=True)
    class Options(NominalGeometry):
        """Options of the ``lidar`` sensor.

        Attributes
        ----------
        beams : int
            Number of laser beams (elevations). Default 64.
        fov_up, fov_down : float
            Elevation of the top and bottom beam, degrees (up positive). Default +2 / -24.8.
        azimuth_step : float
            Horizontal angular resolution, degrees. Default 0.2.
        min_range, max_range : float
            Returns outside this range (metres) are lost. Default 0.5 / 120.
        dropout : float
            Probability that a return is lost, in [0, 1). Default 0.
        noise_m : float
            Std of Gaussian range noise, metres. Default 0.
        pose : str or (float, float, float)
            The LiDAR origin in the left camera frame (metres; x right, y down,
            z forward) or a name from :data:`LIDAR_POSES` (``kitti``). Default
            ``(0, 0, 0)``: at the camera centre.
        rotation : (float, float, float)
            LiDAR orientation: rotations (degrees) about the camera's x, y and z
            axes (applied x first); the beams' azimuth and elevation are measured
            in the rotated frame. Default ``(0, 0, 0)``.
        zbuffer : bool
            Cast the beams against the z-buffered surface even at pose zero (what
            every other pose does; its 2 x 2 splat also closes the gaps of a sparse
            ground truth, so the scan is as dense as an offset one). Default False:
            at pose zero the ground truth is sampled at the beams' pixels.
        nominal_f, nominal_baseline : float
            Focal length (px) and baseline (m) assumed for uncalibrated frames.
        """

        beams: Annotated[int, Range(1)] = 64
        fov_up: Annotated[float, Range(-90.0, 90.0, lo_open=True, hi_open=True)] = 2.0
        fov_down: Annotated[float, Range(-90.0, 90.0, lo_open=True, hi_open=True)] = -24.8
        azimuth_step: Annotated[float, Range(0.0, 10.0, lo_open=True)] = 0.2
        min_range: Annotated[float, _NON_NEGATIVE] = 0.5
        max_range: Annotated[float, _POSITIVE] = 120.0
        dropout: Annotated[float, _PROBABILITY] = 0.0
        noise_m: Annotated[float, _NON_NEGATIVE] = 0.0
        pose: str | tuple[float, float, float] = (0.0, 0.0, 0.0)
        rotation: Annotated[tuple[float, float, float], Each(Range(-180.0, 180.0))] = (0.0, 0.0, 0.0)
        zbuffer: bool = False

        def cross_check(self) -> None:
            """A known pose preset or a translation within 100 m; ``fov_down`` below ``fov_up``; the range."""
            if isinstance(self.pose, str):
                if self.pose not in LIDAR_POSES:
                    raise reject("pose", self.pose, "one of " + ", ".join(repr(p) for p in sorted(LIDAR_POSES)))
            elif len(self.pose) != 3 or not all(np.isfinite(v) and abs(v) <= 100 for v in self.pose):
                raise reject("pose", self.pose, "[tx, ty, tz] in metres (|t| <= 100) or a preset name")
            if not self.fov_down < self.fov_up:
                raise reject("fov_down", self.fov_down, f"< fov_up ({self.fov_up})")
            _check_range(self.min_range, self.max_range)

    def translation(self) -> np.ndarray:
        """The LiDAR origin in the left camera frame (metres), the preset's values for a named ``pose``."""
        pose = self.options.pose
        return np.array(LIDAR_POSES[pose] if isinstance(pose, str) else pose, np.float64)

    def rotation(self) -> np.ndarray:
        """3 x 3 rotation from the LiDAR frame to the left camera frame."""
        return rotation_matrix(self.options.rotation)

    @property
    def offset(self) -> bool:
        """Whether the LiDAR is mounted away from the camera centre (or rotated)."""
        return bool(np.any(self.translation() != 0) or any(a != 0 for a in self.options.rotation))

    def sees_past_edges(self) -> bool:
        """True when the LiDAR is mounted away from the camera centre (:attr:`offset`)."""
        return self.offset

    def elevations(self) -> np.ndarray:
        """Beam elevations in degrees, top beam first."""
        o = self.options
        return np.linspace(o.fov_up, o.fov_down, o.beams) if o.beams > 1 else np.array([o.fov_up])

    def simulate(self, frame: StereoFrame, seed: int = 0) -> StereoFrame:
        """Cast the beams through the image and measure their ranges (see :meth:`Sensor.simulate`)."""
        gt, rng = self._begin(frame, seed)
        if self.offset or self.options.zbuffer:
            return self._simulate_rendered(frame, gt, rng)
        o = self.options
        h, w = frame.shape
        f, b, doffs, cx, cy = self._geometry(frame)
        u, v = self._beam_pixels(h, w, f, cx, cy)
        cols = np.floor(u + 0.5).astype(np.int64).ravel()
        rows = np.floor(v + 0.5).astype(np.int64).ravel()
        inside = (cols >= 0) & (cols < w) & (rows >= 0) & (rows < h)
        rows, cols = rows[inside], cols[inside]
        # one return per pixel (the first beam/azimuth that lands there)
        _, first = np.unique(rows * w + cols, return_index=True)
        rows, cols = rows[np.sort(first)], cols[np.sort(first)]
        rows, cols, z = self._true_depth(gt, rows, cols, f=f, b=b, doffs=doffs)
        ray = np.sqrt(1.0 + ((cols - cx) / f) ** 2 + ((rows - cy) / f) ** 2)
        r = z * ray
        keep = (r >= o.min_range) & (r <= o.max_range) & np.isfinite(r) & (z > 0)
        drop = rng.random(r.size) < o.dropout
        noise = rng.normal(0.0, o.noise_m, size=r.size) if o.noise_m > 0 else np.zeros(r.size)
        keep &= ~drop
        r_meas = r + noise
        keep &= r_meas > 0
        z_meas = r_meas / ray
        d_meas = self._measured_disparity(z_meas, keep, f, b, doffs)
        rows, cols = rows[keep], cols[keep]
        return self._output(frame, rows, cols, d_meas[keep].astype(np.float32), depth=z_meas[keep].astype(np.float32))

    def _beam_pixels(self, h: int, w: int, f: float, cx: float, cy: float) -> tuple[np.ndarray, np.ndarray]:
        """Where each beam (elevation x azimuth) crosses the image plane: ``u``, ``v`` (beams x azimuths)."""
        step = np.deg2rad(self.options.azimuth_step)
        az_lo, az_hi = np.arctan((-0.5 - cx) / f), np.arctan((w - 0.5 - cx) / f)
        az = np.arange(np.ceil(az_lo / step), np.floor(az_hi / step) + 1) * step
        el = np.deg2rad(self.elevations())
        u = cx + f * np.tan(az)[None, :]
        v = cy - f * np.tan(el)[:, None] / np.cos(az)[None, :]
        u, v = np.broadcast_arrays(u, v)
        return u, v

    def _simulate_rendered(self, frame: StereoFrame, gt: np.ndarray, rng: np.random.Generator) -> StereoFrame:
        """Beams cast from the LiDAR's own pose, the returns projected into the left camera (module docs)."""
        o = self.options
        h, w = frame.shape
        f, b, doffs, cx, cy = self._geometry(frame)
        rot, t = self.rotation(), self.translation()
        zbuf = render_lidar_depth(gt, rot, t, f=f, b=b, doffs=doffs, cx=cx, cy=cy)
        # the beams in the LiDAR's virtual image (the left camera's intrinsics at the LiDAR's pose)
        u, v = (a.ravel() for a in self._beam_pixels(h, w, f, cx, cy))
        cols, rows = np.floor(u + 0.5).astype(np.int64), np.floor(v + 0.5).astype(np.int64)
        inside = (cols >= 0) & (cols < w) & (rows >= 0) & (rows < h)
        u, v, z_l = u[inside], v[inside], zbuf[rows[inside], cols[inside]]
        hit = np.isfinite(z_l)
        # the return: along the beam's exact direction, at the surface's depth there
        ray = np.stack([(u[hit] - cx) / f, (v[hit] - cy) / f, np.ones(int(hit.sum()))])
        r = z_l[hit] * np.sqrt((ray**2).sum(axis=0))
        keep = (r >= o.min_range) & (r <= o.max_range)
        keep &= ~(rng.random(r.size) < o.dropout)
        r_meas = r + (rng.normal(0.0, o.noise_m, size=r.size) if o.noise_m > 0 else 0.0)
        keep &= r_meas > 0
        p_l = ray[:, keep] * (r_meas[keep] / np.sqrt((ray[:, keep] ** 2).sum(axis=0)))
        p_c = rot @ p_l + t.reshape(3, 1)
        front = p_c[2] > 0
        p_c = p_c[:, front]
        z_c = p_c[2]
        cols = np.floor(cx + f * p_c[0] / z_c + 0.5).astype(np.int64)
        rows = np.floor(cy + f * p_c[1] / z_c + 0.5).astype(np.int64)
        inside = (cols >= 0) & (cols < w) & (rows >= 0) & (rows < h)
        rows, cols, z_c = rows[inside], cols[inside], z_c[inside]
        # where several returns land on one pixel the nearest wins (as a real scan is projected)
        order = np.lexsort((z_c, rows * w + cols))
        _, first = np.unique((rows * w + cols)[order], return_index=True)
        pick = order[first]
        rows, cols, z_c = rows[pick], cols[pick], z_c[pick]
        disp = f * b / z_c - doffs
        return self._output(frame, rows, cols, disp.astype(np.float32), depth=z_c.astype(np.float32))


@SENSORS.register("tof")
class ToFSensor(Sensor["ToFSensor.Options"]):
    """Low-resolution time-of-flight camera registered to the left view (see module docs)."""

    name = "tof"

    @dataclass(frozen=True)
    class Options(NominalGeometry):
        """Options of the ``tof`` sensor.

        Attributes
        ----------
        grid_w, grid_h : int
            Sensor resolution; one measurement at the centre of each cell of a
            ``grid_w`` x ``grid_h`` grid over the image. Default 80 x 60.
        min_range, max_range : float
            Depth limits (metres). Default 0.1 / 8.
        noise_k : float
            Depth noise ``sigma = noise_k * z**2`` (1/m). Default 0.
        dropout : float
            Probability that a measurement is lost, in [0, 1). Default 0.
        nominal_f, nominal_baseline : float
            Focal length (px) and baseline (m) assumed for uncalibrated frames.
        """

        grid_w: Annotated[int, Range(1)] = 80
        grid_h: Annotated[int, Range(1)] = 60
        min_range: Annotated[float, _NON_NEGATIVE] = 0.1
        max_range: Annotated[float, _POSITIVE] = 8.0
        noise_k: Annotated[float, _NON_NEGATIVE] = 0.0
        dropout: Annotated[float, _PROBABILITY] = 0.0

        def cross_check(self) -> None:
            """``max_range`` beyond ``min_range``."""
            _check_range(self.min_range, self.max_range)

    def simulate(self, frame: StereoFrame, seed: int = 0) -> StereoFrame:
        """Measure the depth at the centres of the ``grid_w`` x ``grid_h`` cells (see :meth:`Sensor.simulate`)."""
        gt, rng = self._begin(frame, seed)
        o = self.options
        h, w = frame.shape
        f, b, doffs, _, _ = self._geometry(frame)
        cs = np.minimum(((np.arange(o.grid_w) + 0.5) * w / o.grid_w).astype(np.int64), w - 1)
        rs = np.minimum(((np.arange(o.grid_h) + 0.5) * h / o.grid_h).astype(np.int64), h - 1)
        rows, cols = (a.ravel() for a in np.meshgrid(rs, cs, indexing="ij"))
        flat = np.unique(rows * w + cols)
        rows, cols = np.divmod(flat, w)
        rows, cols, z = self._true_depth(gt, rows, cols, f=f, b=b, doffs=doffs)
        keep = (z >= o.min_range) & (z <= o.max_range)
        keep &= ~(rng.random(z.size) < o.dropout)
        noise = rng.normal(0.0, 1.0, size=z.size) * o.noise_k * z**2 if o.noise_k > 0 else np.zeros(z.size)
        z_meas = z + noise
        keep &= z_meas > 0
        d_meas = self._measured_disparity(z_meas, keep, f, b, doffs)
        return self._output(
            frame, rows[keep], cols[keep], d_meas[keep].astype(np.float32), depth=z_meas[keep].astype(np.float32)
        )


def build_sensor(name: str, options: Mapping[str, object] | None = None) -> Sensor[NominalGeometry]:
    """Build a registered sensor from an option mapping.

    Parameters
    ----------
    name : str
        ``uniform``, ``lidar`` or ``tof`` (see ``SENSORS.names()``).
    options : Mapping or None
        Option values (see each sensor's ``Options``); validated with
        :func:`vpp_service.settings.from_mapping` under section ``sensor.<name>``.

    Raises
    ------
    ValueError
        Unknown sensor (lists the known ones) or invalid option (``SettingsError``).
    """
    cls = SENSORS.get(name)
    return cls(from_mapping(cls.Options, options, f"sensor.{name}"))


__all__ = [
    "LIDAR_POSES",
    "SENSORS",
    "LidarSensor",
    "NominalGeometry",
    "Sensor",
    "ToFSensor",
    "UniformSensor",
    "build_sensor",
]
