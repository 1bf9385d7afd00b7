"""The evaluation runner: matcher alone vs guided stereo vs VPP on the same points.

For every frame (and every density of a sweep) the runner

1. draws the sparse points **once** with the sensor (seeded with ``seed``, the
   same seed for every scene, so filtering scenes does not change the points);
2. runs each method on the same frame and points, each one call of the fusion
   step :func:`vpp_service.fusion.fuse` (``protocol=True``):

   * ``baseline`` - the matcher on the raw pair (independent of the points,
     so computed once per scene and repeated for each density of a sweep);
   * ``guided`` - the matcher with the points as ``hints`` (only matchers
     with ``supports_guidance``);
   * ``vpp`` - VPP on the points (pattern seed ``seed``), then the matcher on
     the painted pair;

   Before the first method is timed, the matcher runs once untimed on the
   first frame (:meth:`~vpp_service.matchers.Matcher.warm_up`): a network's
   engine opens and compiles on its first pair, which is no method's cost;

3. fills the matcher's holes with background interpolation
   (:func:`vpp_service.matchers.fill_holes`), as the protocol says, and scores
   with :func:`~vpp_service.metrics.compute_metrics` over all
   valid-GT pixels, plus ``*_nocc`` metrics when the frame has a mask
   (:func:`vpp_service.fusion.score`).

Matcher disparity range: when the matcher is given by name, each scene gets
``max_disparity`` = the given value, or by default the smallest multiple of 16
strictly above the scene's largest ground-truth disparity (at least 16, at
most width - 1, and at most the matcher's ``max_range``: a network's fixed range).

Before VPP and guidance the points pass the see-through filter
(``depth_filter``, :class:`~vpp_service.vpp.see_through.DepthFilter`; by default
``auto``: the points of LiDAR-like sensors, i.e. ``lidar`` with a ``pose`` and a
dataset's own LiDAR scan); a row's ``see_through`` counts the points it dropped (absent when
it did not run), ``n_points`` counts the points before it.

Densities apply to the ``uniform`` sensor (fraction of valid GT pixels). Other
sensors (``lidar``, ``tof``) take one run with ``densities=None`` and report
the measured fraction of valid-GT pixels that got a point as ``density``;
``sensor="frame"`` uses the frame's own ``sparse_disparity`` (a real scan).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import TYPE_CHECKING, Union, cast

import numpy as np

from vpp_service.frame import StereoFrame
from vpp_service.vpp.see_through import LIDAR_LIKE

if TYPE_CHECKING:
    from vpp_service.datasets.base import Dataset
    from vpp_service.matchers.base import Matcher
    from vpp_service.sources.sensors import NominalGeometry, Sensor
    from vpp_service.vpp import VPPConfig
    from vpp_service.vpp.see_through import DepthFilter

#: What :func:`run_evaluation` reads frames from.
Frames = Union["Dataset", StereoFrame, Iterable[StereoFrame]]

#: Methods understood by :func:`run_evaluation`, in report order.
METHODS = ("baseline", "guided", "vpp")

#: ``progress(done, total, label)`` - called before each step.
Progress = Callable[[int, int, str], None]

#: One value of a result row: a name (``scene``, ``method``, ...), a count or a
#: metric, or None (``density`` of a sensor without one in a report).
RowValue = str | float | None
#: One result row of :func:`run_evaluation` (fields listed there).
ResultRow = dict[str, RowValue]


def default_max_disparity(gt: np.ndarray, width: int, limit: int | None = None) -> int:
    """Smallest multiple of 16 strictly above ``max(gt)`` (>= 16, <= width - 1, <= ``limit`` when given).

    ``limit``: the matcher's :attr:`~vpp_service.matchers.Matcher.max_range` (a network's fixed range).
    """
    finite = gt[np.isfinite(gt)]
    top = float(finite.max()) if finite.size else 0.0
    d = max(16, int(math.floor(top / 16.0) + 1) * 16)
    return int(min(d, width - 1, limit if limit is not None else d))


def _frames(source: Frames) -> tuple[int, Callable[[int], StereoFrame]]:
    if isinstance(source, StereoFrame):
        return 1, lambda i: source
    if hasattr(source, "__len__") and hasattr(source, "__getitem__"):
        indexed = cast("Dataset | Sequence[StereoFrame]", source)
        return len(indexed), lambda i: indexed[i]
    if isinstance(source, Iterable):
        items = list(source)
        return len(items), items.__getitem__
    raise TypeError(
        f"frames_or_dataset: must be a Dataset, a StereoFrame or an iterable of them, got {type(source).__name__}"
    )


def _check_methods(methods: Sequence[str]) -> list[str]:
    if isinstance(methods, str):
        methods = [m.strip() for m in methods.split(",") if m.strip()]
    methods = list(methods)
    if not methods:
        raise ValueError(f"methods: must name at least one of {', '.join(METHODS)}")
    bad = [m for m in methods if m not in METHODS]
    if bad:
        raise ValueError(f"methods: unknown {bad}; known: {', '.join(METHODS)}")
    if len(set(methods)) != len(methods):
        raise ValueError(f"methods: duplicates in {methods}")
    return methods


def _check_densities(densities: float | Sequence[float] | None, sensor_name: str | None) -> list[float | None]:
    if densities is None:
        return [None]
    if isinstance(densities, (int, float)) and not isinstance(densities, bool):
        densities = [densities]
    densities = list(densities)  # type: ignore[arg-type]  # a bool is rejected below
    if not densities:
        raise ValueError("densities: must not be empty (use None for sensors without a density)")
    if densities == [None]:
        if sensor_name == "uniform":
            raise ValueError("densities: the uniform sensor needs a density")
        return [None]
    if sensor_name != "uniform":
        raise ValueError(f"densities: only the uniform sensor takes densities; pass None for {sensor_name!r}")
    for d in densities:
        if isinstance(d, bool) or not isinstance(d, (int, float)) or not np.isfinite(d) or not 0 < d <= 1:
            raise ValueError(f"densities: each must be in (0, 1], got {d!r}")
    return [float(d) for d in densities]


def _resolve_matcher(
    matcher: str | Matcher, matcher_options: Mapping[str, object] | None
) -> tuple[str, Matcher | None, dict[str, object], Matcher]:
    """Check the matcher argument: ``(name, ready matcher or None, options to build it by name, a built one)``.

    A matcher given by name is built once here with ``matcher_options`` (less
    ``max_disparity``) so that a bad name or option fails before any frame; the
    built one tells the guidance support and the range limit (``max_range``).
    """
    from vpp_service.matchers import Matcher, build_matcher

    if isinstance(matcher, str):
        base_opts = dict(matcher_options or {})
        probe = build_matcher(matcher, {k: v for k, v in base_opts.items() if k != "max_disparity"})
        return matcher, None, base_opts, probe
    if isinstance(matcher, Matcher):
        if matcher_options:
            raise ValueError("matcher_options: only used when the matcher is given by name")
        return matcher.name, matcher, {}, matcher
    raise TypeError(f"matcher: must be a matcher name or a Matcher, got {type(matcher).__name__}")


def _resolve_sensors(
    sensor: str | Sensor[NominalGeometry],
    sensor_options: Mapping[str, object] | None,
    densities: float | Sequence[float] | None,
) -> tuple[str, list[tuple[float | None, Sensor[NominalGeometry] | None]]]:
    """Check the sensor and densities: ``(sensor name, [(density, sensor or None for the frame's own points)])``."""
    from vpp_service.sources.sensors import Sensor, build_sensor

    if isinstance(sensor, str):
        sensor_name = sensor
        if sensor != "frame":
            from vpp_service.sources.sensors import SENSORS

            SENSORS.get(sensor)
    elif isinstance(sensor, Sensor):
        sensor_name = sensor.name
        if sensor_options:
            raise ValueError("sensor_options: only used when the sensor is given by name")
    else:
        raise TypeError(f"sensor: must be a sensor name or a Sensor, got {type(sensor).__name__}")
    sensors: list[tuple[float | None, Sensor[NominalGeometry] | None]] = []
    for d in _check_densities(densities, sensor_name if isinstance(sensor, str) else None):
        if isinstance(sensor, Sensor):
            sensors.append((d, sensor))
        elif sensor == "frame":
            sensors.append((d, None))
        else:
            opts = dict(sensor_options or {})
            if d is not None:
                opts["density"] = d
            sensors.append((d, build_sensor(sensor, opts)))
    return sensor_name, sensors


def _check_run_args(seed: int, max_disparity: int | None, progress: Progress | None) -> None:
    """Check the scalar arguments of :func:`run_evaluation` (raise ValueError / TypeError naming them)."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed: must be an integer >= 0, got {seed!r}")
    if max_disparity is not None and (
        isinstance(max_disparity, bool) or not isinstance(max_disparity, int) or max_disparity < 1
    ):
        raise ValueError(f"max_disparity: must be a positive integer, got {max_disparity!r}")
    if progress is not None and not callable(progress):
        raise TypeError("progress: must be callable")


def _check_vpp_config(vpp_config: VPPConfig | None, matcher: Matcher) -> VPPConfig:
    """The VPP configuration to run (for None: the matcher's preferred setting over VPP's defaults)."""
    from vpp_service.settings import from_mapping
    from vpp_service.vpp import VPPConfig

    if vpp_config is None:
        return from_mapping(VPPConfig, matcher.preferred_vpp(matcher.options), f"matcher.{matcher.name}: vpp")
    if not isinstance(vpp_config, VPPConfig):
        raise TypeError(f"vpp_config: must be a VPPConfig or None, got {type(vpp_config).__name__}")
    return vpp_config


def _check_depth_filter(depth_filter: DepthFilter | str | None) -> DepthFilter | None:
    """The filter to run (None: never) from a ``DepthFilter``, a mode name or None."""
    from vpp_service.vpp.see_through import FILTER_MODES, DepthFilter

    if depth_filter is None or isinstance(depth_filter, DepthFilter):
        return depth_filter
    if isinstance(depth_filter, str):
        if depth_filter not in FILTER_MODES:
            raise ValueError(f"depth_filter: must be one of {', '.join(FILTER_MODES)}, got {depth_filter!r}")
        return DepthFilter(mode=depth_filter)  # type: ignore[arg-type]  # checked against FILTER_MODES above
    raise TypeError(f"depth_filter: must be a DepthFilter, a mode name or None, got {type(depth_filter).__name__}")


def _frame_with_gt(get: Callable[[int], StereoFrame], i: int) -> tuple[StereoFrame, np.ndarray]:
    """Frame ``i`` and its ground truth (raise when the item is not a frame or has none)."""
    frame = get(i)
    if not isinstance(frame, StereoFrame):
        raise TypeError(f"frames_or_dataset: item {i} is a {type(frame).__name__}, not a StereoFrame")
    if frame.gt_disparity is None:
        raise ValueError(f"frames_or_dataset: frame {frame.name or i!r} has no gt_disparity to score against")
    return frame, frame.gt_disparity


def _draw_points(
    frame: StereoFrame, sensor: Sensor[NominalGeometry] | None, seed: int, scene: str
) -> tuple[np.ndarray, dict[str, object]]:
    """The sparse points of one run (H x W float32, NaN where no point or not ``0 < d``) and the drawn frame's meta."""
    drawn = frame if sensor is None else sensor.simulate(frame, seed=seed)
    if drawn.sparse_disparity is None:
        raise ValueError(f"sensor: 'frame' needs sparse_disparity, frame {scene!r} has none")
    sparse = drawn.sparse_disparity.astype(np.float32)
    return np.where(np.isfinite(sparse) & (sparse > 0), sparse, np.nan).astype(np.float32), drawn.meta


def _scene_matcher(
    name: str, options: Mapping[str, object], gt: np.ndarray, *, max_disparity: int | None, limit: int | None
) -> Matcher:
    """Matcher ``name`` built for one scene: ``max_disparity``, else the scene's :func:`default_max_disparity`."""
    from vpp_service.matchers import build_matcher

    md = max_disparity if max_disparity is not None else default_max_disparity(gt, gt.shape[1], limit)
    return build_matcher(name, {**options, "max_disparity": int(md), "fill": False})


def _runtime_fields(matcher: Matcher) -> ResultRow:
    """``engine``, ``device``, ``precision``: what runs ``matcher`` (:meth:`~vpp_service.matchers.Matcher.runtime`)."""
    runtime = matcher.runtime()
    return {"engine": runtime["engine"], "device": runtime["device"], "precision": runtime["precision"]}


class EvaluationInterrupted(KeyboardInterrupt):
    """Ctrl-C during :func:`run_evaluation`: the rows of the scenes that finished, to save as a partial result.

    Attributes
    ----------
    rows : list of ResultRow
        Every row of the first ``scenes_done`` scenes (a scene half done is left out).
    scenes_done, scenes_total : int
        How many scenes finished, of how many.
    """

    def __init__(self, rows: list[ResultRow], scenes_done: int, scenes_total: int) -> None:
        super().__init__(f"interrupted after {scenes_done} of {scenes_total} scenes")
        self.rows = rows
        self.scenes_done = scenes_done
        self.scenes_total = scenes_total


def _check_matcher_fits(name: str, probe: Matcher, methods: Sequence[str], max_disparity: int | None) -> int | None:
    """The matcher's fixed disparity range (None: any); raises when the methods or the range ask too much.

    Raises
    ------
    ValueError
        ``guided`` with a matcher that has no cost volume to modulate (a network), or a
        ``max_disparity`` above the matcher's range.
    """
    if "guided" in methods and not probe.supports_guidance:
        raise ValueError(
            f"methods: 'guided' needs a matcher with guidance support (it modulates the matcher's cost volume); "
            f"{name!r} has none"
        )
    limit = probe.max_range
    if max_disparity is not None and limit is not None and max_disparity > limit:
        raise ValueError(f"max_disparity: {max_disparity} exceeds the disparity range of {name!r} ({limit})")
    return limit


def run_evaluation(
    frames_or_dataset: Frames,
    matcher: str | Matcher = "census-sgm",
    methods: Sequence[str] = METHODS,
    densities: float | Sequence[float] | None = (0.05,),
    sensor: str | Sensor[NominalGeometry] = "uniform",
    *,
    vpp_config: VPPConfig | None = None,
    seed: int = 0,
    progress: Progress | None = None,
    matcher_options: Mapping[str, object] | None = None,
    sensor_options: Mapping[str, object] | None = None,
    max_disparity: int | None = None,
    dataset_name: str | None = None,
    depth_filter: DepthFilter | str | None = "auto",
) -> list[ResultRow]:
    """Evaluate methods on frames with ground truth.

    Parameters
    ----------
    frames_or_dataset : Dataset, StereoFrame or iterable of StereoFrame
        Frames with ``gt_disparity``. A dataset is read lazily, one frame at a time.
    matcher : str or Matcher
        Registered matcher name (built per scene with ``matcher_options`` and
        the scene's ``max_disparity``) or a ready matcher (used as is).
    methods : sequence of str or comma string
        Subset of ``baseline``, ``guided``, ``vpp``.
    densities : float, sequence of float or None
        Densities of the ``uniform`` sensor (a sweep when several); None for other sensors.
    sensor : str or Sensor
        ``uniform``, ``lidar``, ``tof`` (built with ``sensor_options``), ``frame``
        (the frame's own ``sparse_disparity``) or a ready sensor.
    vpp_config : VPPConfig or None
        VPP variant (None = the matcher's ``preferred_vpp`` over VPPConfig's defaults).
    seed : int
        Seed of the sensor draw and of VPP's random pattern (>= 0).
    progress : callable or None
        ``progress(done, total, label)``, e.g. :class:`~vpp_service.evaluation.progress.ProgressBar`.
    matcher_options, sensor_options : Mapping or None
        Options for building the matcher / sensor by name.
    max_disparity : int or None
        Matcher disparity range for every scene (None = per-scene default, see module docs).
    dataset_name : str or None
        Value of the ``dataset`` field (default: ``frame.meta["dataset"]``).
    depth_filter : DepthFilter, str or None
        The see-through filter before VPP / guidance: a ``DepthFilter``, or a
        mode (``auto``, the default: LiDAR-like points only; ``see-through``;
        ``none``) with the default window; None = ``none``.

    Returns
    -------
    list of dict
        One row per (scene, density, method): ``dataset``, ``scene``, ``method``,
        ``matcher``, ``sensor``, ``density``, ``bad1``..``bad4``, ``avg``, ``rms``,
        ``invalid``, ``n``, ``*_nocc`` variants (when masked), ``n_points``,
        ``max_disparity``, ``ms`` (VPP + matching wall time, after one untimed
        warm-up pass of the matcher on the first frame), ``see_through``
        (points the filter dropped, when it ran), and ``engine``, ``device``,
        ``precision``: what ran the matcher (:meth:`~vpp_service.matchers.Matcher.runtime`).

    Raises
    ------
    TypeError, ValueError
        Bad arguments: unknown method, ``guided`` with a matcher without
        guidance (names the matcher), frames without ground truth, ...
    """
    from vpp_service.fusion import fuse

    methods = _check_methods(methods)
    _check_run_args(seed, max_disparity, progress)
    matcher_name, ready, base_opts, probe = _resolve_matcher(matcher, matcher_options)
    limit = _check_matcher_fits(matcher_name, probe, methods, None if ready is not None else max_disparity)
    sensor_name, sensors = _resolve_sensors(sensor, sensor_options, densities)
    point_filter = _check_depth_filter(depth_filter)
    if "vpp" in methods:
        vpp_config = _check_vpp_config(vpp_config, probe)

    n_frames, get = _frames(frames_or_dataset)
    if n_frames == 0:
        raise ValueError("frames_or_dataset: no frames to evaluate")
    total = n_frames * (("baseline" in methods) + len(sensors) * sum(m != "baseline" for m in methods))
    done = 0
    rows: list[ResultRow] = []

    def tick(label: str) -> None:
        if progress is not None:
            progress(done, total, label)

    finished, scenes_done = 0, 0  # rows of the scenes whose every method is done
    try:
        for i in range(n_frames):
            frame, gt = _frame_with_gt(get, i)
            scene = frame.name or f"frame{i}"
            m = ready or _scene_matcher(matcher_name, base_opts, gt, max_disparity=max_disparity, limit=limit)
            if i == 0:  # untimed: a network's engine opens and compiles on its first pair, kernels allocate
                m.warm_up(frame.left, frame.right)
            common: ResultRow = {
                "dataset": dataset_name or frame.meta.get("dataset", ""),
                "scene": scene,
                "matcher": matcher_name,
                "sensor": sensor_name,
                "max_disparity": int(m.options.max_disparity),
                **_runtime_fields(m),
            }

            baseline_row: ResultRow = {}
            if "baseline" in methods:
                tick(f"{scene} {matcher_name} baseline")
                res = fuse(frame, m, None, depth=False, protocol=True)
                baseline_row = {**res.metrics, "ms": res.timing_ms["match"]}
                done += 1

            for d, s in sensors:
                sparse, drawn_meta = _draw_points(frame, s, int(seed), scene)
                n_points = int(np.isfinite(sparse).sum())
                n_valid = int((np.isfinite(gt) & (gt > 0)).sum())
                density = d if d is not None else (n_points / n_valid if n_valid else 0.0)
                base: ResultRow = {**common, "density": density, "n_points": n_points}
                dlabel = f"{d:g}" if d is not None else sensor_name
                with_points = frame.with_(
                    sparse_disparity=sparse,
                    sensor_depth=None,
                    meta={**frame.meta, LIDAR_LIKE: drawn_meta.get(LIDAR_LIKE) is True},
                )
                for method in methods:
                    if method == "baseline":
                        rows.append({**base, "method": "baseline", **baseline_row})
                        continue
                    tick(f"{scene} {matcher_name} {method} {dlabel}")
                    guided = method == "guided"  # guidance instead of painting: no VPP config, no pattern seed
                    res = fuse(
                        with_points,
                        m,
                        None if guided else vpp_config,
                        seed=int(seed),
                        guide=guided,
                        depth=False,
                        protocol=True,
                        depth_filter=point_filter,
                    )
                    ms = res.timing_ms.get("vpp", 0.0) + res.timing_ms["match"]
                    extra: ResultRow = {f"vpp_{k}": v for k, v in res.vpp_stats.items()}
                    extra |= {} if res.see_through is None else {"see_through": res.see_through}
                    rows.append({**base, "method": method, **res.metrics, "ms": ms, **extra})
                    done += 1
            finished, scenes_done = len(rows), i + 1
    except KeyboardInterrupt:
        raise EvaluationInterrupted(rows[:finished], scenes_done, n_frames) from None
    if progress is not None:
        progress(done, total, "done")
    return rows


__all__ = ["METHODS", "EvaluationInterrupted", "ResultRow", "RowValue", "default_max_disparity", "run_evaluation"]
