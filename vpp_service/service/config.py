"""Service configuration: one TOML file, validated in full before anything starts.

Sections (every key is documented in ``deploy/config.example.toml``)::

    [service]   rig, prefix, max_frames, out, summary, ...      -> ServiceSection
    [zenoh]     enabled, mode, listen, connect, multicast_scouting, config_file
    [source]    type = "sim" | "files" | "zenoh", plus that source's options
    [vpp]       enabled, plus VPPConfig fields (unset ones: the matcher's preferred_vpp, then VPPConfig's)
    [matcher]   name = "sgbm" | "bm" | "census-sgm" | "psmnet" | "onnx", plus that matcher's options;
                max_disparity = "auto" (default) | int, [matcher.auto_range] -> AutoRangeOptions
    [queues]    input_size, input_policy, output_size, output_policy
    [depth_filter] mode = "auto" | "see-through" | "none", window_w, window_h, margin, min_gap
                -> DepthFilter (the see-through filter before VPP)
    [depth_clip] min_depth_m, max_depth_m -> DepthClip (the valid depth range of every output)
    [rectify]   left + right (camera_info YAMLs) | opencv + alpha -> RectifyOptions (raw frames rectified)
    [[sinks]]   type = "zenoh" | "rerun" | "files", plus that sink's options

:func:`load_config` reads a file (or starts from :data:`DEFAULT_CONFIG`, the
embedded default of ``vpp-service run`` with no arguments), applies overrides,
and validates every section with :func:`vpp_service.settings.from_mapping` and
each plugin's own ``parse_options`` (its ``Options`` plus its ``check_options``
hook). Errors are :class:`~vpp_service.settings.SettingsError` naming the key
(``source.rate_hz: got 'fast'; expected a number``).
"""

from __future__ import annotations

import copy
import logging
import os
import re
import tomllib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal, TypeVar

from vpp_service.plugin import Plugin
from vpp_service.queueing import Policy
from vpp_service.registry import Registry
from vpp_service.settings import (
    Each,
    IsFile,
    Matches,
    NonEmpty,
    OptionError,
    Options,
    Range,
    Satisfies,
    SettingsError,
    from_mapping,
    reject,
)

log = logging.getLogger(__name__)

if TYPE_CHECKING:
    from vpp_service.matchers.depth_clip import DepthClip
    from vpp_service.matchers.disparity_range import AutoRangeOptions
    from vpp_service.rectify import RectifyOptions
    from vpp_service.vpp import VPPConfig
    from vpp_service.vpp.see_through import DepthFilter

T = TypeVar("T")
P = TypeVar("P", bound=Plugin)

#: ``parse(name, raw_options, section)``: a plugin's parsed ``Options`` (raises SettingsError).
ParseOptions = Callable[[str, Mapping[str, Any], str], object]

#: A rig name: it becomes a Zenoh key part, a Rerun entity and part of file names, so a plain word
#: (no "..", no separators, at most 64 characters).
RIG_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.\-]{0,63}")

#: The endpoint every command meets on unless told otherwise: ``run`` listens on it, ``publish`` and
#: ``status`` connect to it.
DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"

#: Environment variable that replaces :data:`DEFAULT_ENDPOINT` for every command.
ENDPOINT_ENV = "VPP_SERVICE_ENDPOINT"


def default_endpoint() -> str:
    """The shared default endpoint: ``$VPP_SERVICE_ENDPOINT`` when set, else :data:`DEFAULT_ENDPOINT`."""
    return os.environ.get(ENDPOINT_ENV, "").strip() or DEFAULT_ENDPOINT


#: Top-level tables a config may contain.
SECTIONS = ("service", "zenoh", "source", "vpp", "matcher", "queues", "depth_filter", "depth_clip", "rectify", "sinks")


def _check_prefix(prefix: str) -> None:
    """Raise ValueError unless ``prefix`` makes valid Zenoh keys (:func:`~vpp_service.transport.wire.topic`)."""
    from vpp_service.transport.wire import topic

    topic(prefix, "rig0", "x")


#: A Zenoh endpoint, ``proto/address``.
_ENDPOINT = Satisfies(lambda ep: "/" in ep and bool(ep.split("/", 1)[1]), "an endpoint like 'tcp/HOST:PORT'")


@dataclass(frozen=True)
class ServiceSection(Options):
    """``[service]``: identity and run control.

    Attributes
    ----------
    rig : str
        Rig name: topics are ``<prefix>/<rig>/...``; 1-64 of ``A-Z a-z 0-9 _ . -``,
        starting with a letter, digit or ``_`` (:data:`RIG_NAME`).
    prefix : str
        Zenoh key prefix.
    max_frames : int
        Stop after this many frames processed or rejected; 0 = run until stopped.
    out : str
        Folder for the run's files (summary JSON, default ``.rrd``).
    summary : bool
        Print a live one-line summary on stderr.
    summary_period_s : float
        Period of the live summary line and of the summary JSON rewrite.
    shutdown_timeout_s : float
        Bound on every shutdown step (source, threads, each sink).
    timing_window : int
        Frames in the sliding window of the timing statistics.
    reject_log_period_s : float
        At most one log line per this period about rejected inputs (0: a line for every one).
    seed : int
        Seed of the VPP pattern (frame ``seq`` is added).
    reuse_memory : bool
        Keep freed frame buffers in the process for the next frames instead of
        returning them to the kernel (glibc ``mallopt``; see
        :mod:`vpp_service.service.allocator`): fewer page faults per frame, a
        resident size at the stream's peak.
    overwrite : bool
        Start even when ``out`` holds a previous run's outputs (summary.json, a .rrd, recorded
        frames), replacing them (wins over ``resume``). False (default): see ``resume``.
    resume : bool or "auto"
        Start in an ``out`` that holds a previous run's outputs by keeping them: the previous
        ``summary.json`` becomes ``summary.1.json`` (at most :data:`~vpp_service.service.resume.KEEP_SUMMARIES`
        kept), a Rerun ``save`` recording is rotated as its size cap does, the files and record
        sinks go on writing into their folders (:mod:`vpp_service.service.resume`). False:
        ``vpp-service run`` refuses and names them (exit 2). ``"auto"`` (default): true for a
        network source (``zenoh``, ``ros2``: a long-running service), false otherwise (a one-shot run).
    """

    rig: Annotated[str, Matches(RIG_NAME.pattern, "1-64 of A-Z a-z 0-9 _ . - starting with a letter, digit or _")] = (
        "rig0"
    )
    prefix: Annotated[str, Satisfies(_check_prefix, "a plain key expression (no *, $, #, ?, leading/trailing /)")] = (
        "vpp"
    )
    max_frames: Annotated[int, Range(0)] = 0
    out: Annotated[str, NonEmpty()] = "vpp-run"
    summary: bool = True
    summary_period_s: Annotated[float, Range(0.0, 3600.0, lo_open=True)] = 1.0
    shutdown_timeout_s: Annotated[float, Range(0.0, 3600.0, lo_open=True)] = 5.0
    timing_window: Annotated[int, Range(1, 100000)] = 200
    reject_log_period_s: Annotated[float, Range(0.0, 3600.0)] = 5.0
    seed: int = 0
    reuse_memory: bool = True
    overwrite: bool = False
    resume: bool | Literal["auto"] = "auto"


@dataclass(frozen=True)
class ZenohSection(Options):
    """``[zenoh]``: the service's Zenoh session.

    Attributes
    ----------
    enabled : bool
        Open a session (needed by the zenoh source/sink and ``@status``).
    mode : {"peer", "client", "router"}
        Zenoh mode.
    listen, connect : list of str
        Endpoints, e.g. ``"tcp/127.0.0.1:7447"``; ``listen`` defaults to :func:`default_endpoint`.
    multicast_scouting : bool
        Multicast peer discovery; off by default (explicit endpoints only).
    config_file : str
        Optional Zenoh JSON5 config loaded first (the keys above override it).
    max_message_mb : float
        Largest message the session accepts from the network (Zenoh's
        ``transport/link/rx/max_message_size``, plus 64 KiB for Zenoh's own
        headers): Zenoh drops a larger message before assembling it, so it
        never costs memory here. Keep it at least the zenoh source's
        ``max_message_mb`` (which rejects and counts what lies between).
    """

    enabled: bool = True
    mode: Literal["peer", "client", "router"] = "peer"
    listen: Annotated[list[str], Each(_ENDPOINT)] = field(default_factory=lambda: [default_endpoint()])
    connect: Annotated[list[str], Each(_ENDPOINT)] = field(default_factory=list)
    multicast_scouting: bool = False
    config_file: Annotated[str, IsFile()] = ""
    max_message_mb: Annotated[float, Range(0.0, 4096.0, lo_open=True)] = 64.0

    def cross_check(self) -> None:
        """A client connects somewhere."""
        if self.mode == "client" and not self.connect:
            raise reject("connect", self.connect, "at least one endpoint in client mode")


@dataclass(frozen=True)
class QueuesSection(Options):
    """``[queues]``: bounded queues between the pipeline stages.

    Attributes
    ----------
    input_size, output_size : int
        Capacity of the source -> process and process -> sinks queues.
    input_policy, output_policy : {"latest", "block"}
        ``latest`` drops the oldest item when full (live camera: freshest
        frame wins; drops counted); ``block`` makes the producer wait (lossless
        replay; the source slows down instead). See :mod:`vpp_service.queueing`.
        When the config leaves one out, :func:`validate_config` picks it from the
        source: ``block`` for a finite source (``files``, ``rosbag2``: a replay
        loses no frame unless asked), ``latest`` for a live one. The output
        policy also reaches the sinks that buffer (Zenoh, ROS 2, Rerun).
    """

    input_size: Annotated[int, Range(1, 10000)] = 2
    input_policy: Policy = "latest"
    output_size: Annotated[int, Range(1, 10000)] = 4
    output_policy: Policy = "latest"


@dataclass(frozen=True)
class PluginSpec:
    """A validated plugin choice: registered name plus its parsed ``Options``.

    Attributes
    ----------
    name : str
        Registered plugin name.
    options : object
        The plugin's ``Options`` instance (its class depends on the plugin).
    raw : dict
        The option values as given (the form :meth:`ServiceConfig.to_dict` writes back).
    """

    name: str
    options: object
    raw: dict[str, Any]


@dataclass(frozen=True)
class ServiceConfig:
    """The whole validated service configuration."""

    service: ServiceSection
    zenoh: ZenohSection
    source: PluginSpec
    vpp: VPPConfig | None  # None when disabled
    vpp_raw: dict[str, Any]
    matcher: PluginSpec
    queues: QueuesSection
    sinks: tuple[PluginSpec, ...]
    #: ``matcher.max_disparity = "auto"``: how the range is derived per frame (None: the fixed integer).
    disparity_range: AutoRangeOptions | None = None
    #: ``[depth_filter]``: the see-through filter before VPP (None: the defaults, ``mode = "auto"``).
    depth_filter: DepthFilter | None = None
    #: ``[depth_clip]``: the valid depth range of every output (None: :class:`DepthClip`'s defaults).
    depth_clip: DepthClip | None = None
    #: ``[rectify]``: the rig's calibration; its raw frames are rectified before processing (None: frames
    #: arrive rectified, with their own ``calib``).
    rectify: RectifyOptions | None = None

    def to_dict(self) -> dict[str, Any]:
        """Plain mapping (the form :func:`validate_config` accepts)."""
        from vpp_service.settings import to_mapping

        out: dict[str, Any] = {
            "service": to_mapping(self.service),
            "zenoh": to_mapping(self.zenoh),
            "source": {"type": self.source.name, **self.source.raw},
            "vpp": dict(self.vpp_raw),
            "matcher": {"name": self.matcher.name, **self.matcher.raw},
            "queues": to_mapping(self.queues),
            "sinks": [{"type": s.name, **s.raw} for s in self.sinks],
        }
        if self.depth_filter is not None:
            out["depth_filter"] = to_mapping(self.depth_filter)
        if self.depth_clip is not None:
            out["depth_clip"] = to_mapping(self.depth_clip)
        if self.rectify is not None:
            out["rectify"] = to_mapping(self.rectify)
        return out


#: The embedded default of ``vpp-service run``: simulated Motorcycle + uniform 5 %,
#: VPP + SGBM, publishing on a local Zenoh peer and saving ``<out>/vpp.rrd``.
DEFAULT_CONFIG: dict[str, Any] = {
    "service": {"rig": "rig0", "prefix": "vpp", "max_frames": 0, "out": "vpp-run"},
    "zenoh": {"mode": "peer", "connect": [], "multicast_scouting": False},  # listens on default_endpoint()
    "source": {
        "type": "sim",
        "scene": "motorcycle",
        "sensor": "uniform",
        "sensor_options": {"density": 0.05},
        "rate_hz": 10.0,
    },
    "vpp": {"enabled": True},
    "matcher": {"name": "sgbm", "max_disparity": "auto"},
    # no [queues]: the source's defaults (latest for the simulated live camera), `run --source zenoh` picks block
    "sinks": [
        {"type": "zenoh", "outputs": ["disparity", "depth"]},
        {"type": "rerun", "mode": "save", "path": "{out}/vpp.rrd"},
    ],
}


def _table(d: Mapping[str, Any], key: str) -> Mapping[str, Any]:
    v = d.get(key, {})
    if not isinstance(v, Mapping):
        raise OptionError(key, type(v).__name__, "a table")
    return v


def _plugin(d: object, section: str, name_key: str, registry: Registry[T], parse: ParseOptions) -> PluginSpec:
    if not isinstance(d, Mapping):
        raise OptionError(section, type(d).__name__, "a table")
    if name_key not in d:
        raise OptionError(
            f"{section}.{name_key}", "nothing", f"a {registry.kind}: one of {', '.join(registry.names())}"
        )
    name = d[name_key]
    if not isinstance(name, str):
        raise OptionError(f"{section}.{name_key}", repr(name), f"a {registry.kind} name (a string)")
    if name not in registry:
        raise OptionError(
            f"{section}.{name_key}", f"unknown {registry.kind} {name!r}", "one of " + ", ".join(registry.names())
        )
    raw = {k: v for k, v in d.items() if k != name_key}
    return PluginSpec(name=name, options=parse(name, raw, section), raw=raw)


def _require_no_session(section: str, spec: PluginSpec, registry: Registry[P]) -> None:
    """Reject a plugin that needs the Zenoh session when the config disables it."""
    if registry.get(spec.name).needs_session:
        raise SettingsError(f"zenoh.enabled: {section} ({registry.kind} {spec.name!r}) needs a zenoh session")


def _parse_vpp(d: Mapping[str, Any], defaults: Mapping[str, object]) -> VPPConfig | None:
    """The ``[vpp]`` table over the matcher's preferred VPP setting (``Matcher.preferred_vpp``); None if disabled."""
    raw = {**defaults, **d}
    enabled = raw.pop("enabled", True)
    if not isinstance(enabled, bool):
        raise OptionError("vpp.enabled", repr(enabled), "true or false")
    from vpp_service.vpp import VPPConfig

    cfg = from_mapping(VPPConfig, raw, "vpp")
    return cfg if enabled else None


def _parse_matcher_range(raw: Mapping[str, Any], sec: str) -> tuple[dict[str, Any], AutoRangeOptions | None]:
    """Split ``max_disparity`` / ``auto_range`` off a ``[matcher]`` table.

    Returns the matcher's own options (with the fixed ``max_disparity`` when
    one is given) and the :class:`AutoRangeOptions` when the range is
    ``"auto"`` (the default when the key is missing).
    """
    from vpp_service.matchers.disparity_range import AutoRangeOptions

    options = dict(raw)
    md = options.pop("max_disparity", "auto")
    auto_raw = options.pop("auto_range", None)
    if md == "auto":
        if auto_raw is not None and not isinstance(auto_raw, Mapping):
            raise OptionError(f"{sec}.auto_range", type(auto_raw).__name__, "a table")
        return options, from_mapping(AutoRangeOptions, auto_raw or {}, f"{sec}.auto_range")
    if isinstance(md, bool) or not isinstance(md, int):
        raise OptionError(f"{sec}.max_disparity", repr(md), '"auto" or an integer')
    if auto_raw is not None:
        raise OptionError(
            f"{sec}.auto_range", "a table", f'nothing unless max_disparity = "auto" (max_disparity is {md})'
        )
    options["max_disparity"] = md
    return options, None


def validate_config(data: Mapping[str, Any], out: str | None = None) -> ServiceConfig:
    """Validate a whole config mapping (as read from TOML) into a :class:`ServiceConfig`.

    Missing sections take their defaults (sinks default to none). ``{out}`` in
    sink string options is replaced by ``service.out``.

    Raises
    ------
    SettingsError
        Unknown section or key, wrong type, unknown plugin, out-of-range value;
        the message names the key.
    """
    from vpp_service.matchers import MATCHERS, MatcherOptions
    from vpp_service.sinks import SINKS  # registers the built-in sinks
    from vpp_service.sinks.base import parse_sink_options
    from vpp_service.sources import SOURCES, parse_source_options

    if not isinstance(data, Mapping):
        raise OptionError("config", type(data).__name__, "a table")
    unknown = sorted(set(data) - set(SECTIONS))
    if unknown:
        raise OptionError(unknown[0], "an unknown section", "one of " + ", ".join(SECTIONS))
    service = from_mapping(ServiceSection, _table(data, "service"), "service")
    zen = from_mapping(ZenohSection, _table(data, "zenoh"), "zenoh")
    source = _plugin(data.get("source", {"type": "sim"}), "source", "type", SOURCES, parse_source_options)

    ranges: list[AutoRangeOptions] = []

    def parse_matcher(name: str, raw: Mapping[str, Any], sec: str) -> object:
        options, auto = _parse_matcher_range(raw, sec)
        if auto is not None:
            ranges.append(auto)
        return from_mapping(MATCHERS.get(name).Options, options, sec)

    matcher = _plugin(data.get("matcher", {"name": "sgbm"}), "matcher", "name", MATCHERS, parse_matcher)
    vpp_raw = dict(_table(data, "vpp"))
    assert isinstance(matcher.options, MatcherOptions)  # parse_matcher built it
    vpp = _parse_vpp(vpp_raw, MATCHERS.get(matcher.name).preferred_vpp(matcher.options))
    queues_raw = dict(_table(data, "queues"))
    replay: Policy = "block" if SOURCES.get(source.name).finite else "latest"
    for key in ("input_policy", "output_policy"):
        queues_raw.setdefault(key, replay)  # a replay loses nothing unless the config asks for "latest"
    queues = from_mapping(QueuesSection, queues_raw, "queues")
    from vpp_service.vpp.see_through import DepthFilter

    depth_filter = from_mapping(DepthFilter, _table(data, "depth_filter"), "depth_filter")
    from vpp_service.matchers.depth_clip import DepthClip

    depth_clip = from_mapping(DepthClip, _table(data, "depth_clip"), "depth_clip")
    rectify = None
    if "rectify" in data:
        from vpp_service.rectify import RectifyOptions

        rectify = from_mapping(RectifyOptions, _table(data, "rectify"), "rectify")
    sinks_raw = data.get("sinks", [])
    if not isinstance(sinks_raw, list):
        raise OptionError("sinks", type(sinks_raw).__name__, "an array of tables ([[sinks]])")
    sinks: list[PluginSpec] = []
    out_dir = out or service.out
    for i, raw_sink in enumerate(sinks_raw):
        sink = raw_sink
        if isinstance(raw_sink, Mapping):
            sink = {k: (v.replace("{out}", out_dir) if isinstance(v, str) else v) for k, v in raw_sink.items()}
        sinks.append(_plugin(sink, f"sinks[{i}]", "type", SINKS, parse_sink_options))
    if not zen.enabled:
        _require_no_session("source", source, SOURCES)
        for i, spec in enumerate(sinks):
            _require_no_session(f"sinks[{i}]", spec, SINKS)
    return ServiceConfig(
        service=service,
        zenoh=zen,
        source=source,
        vpp=vpp,
        vpp_raw=vpp_raw,
        matcher=matcher,
        queues=queues,
        sinks=tuple(sinks),
        disparity_range=ranges[0] if ranges else None,
        depth_filter=depth_filter,
        depth_clip=depth_clip,
        rectify=rectify,
    )


def previous_outputs(cfg: ServiceConfig) -> list[str]:
    """Files and non-empty folders a run with ``cfg`` would write over: a previous run's outputs.

    ``<out>/summary.json``, the Rerun ``save`` path, and the folders and bags of the
    files, record and rosbag2 sinks. ``vpp-service run`` refuses to start over them
    without ``--overwrite`` (``service.overwrite``) or ``--resume`` (``service.resume``).
    """
    found: list[Path] = []
    summary = Path(cfg.service.out) / "summary.json"
    if summary.exists():
        found.append(summary)
    for spec in cfg.sinks:
        if getattr(spec.options, "mode", "save") != "save":
            continue  # a viewer or a server: nothing on disk
        for key in ("path", "dir"):
            value = getattr(spec.options, key, None)
            if not isinstance(value, str):
                continue
            path = Path(value).expanduser()
            if path.is_file() or (path.is_dir() and any(path.iterdir())):
                found.append(path)
    return [str(p) for p in found]


def check_paths(cfg: ServiceConfig, *, servers_required: bool = True) -> None:
    """Check the paths the configuration names (each plugin's ``check_paths``), before anything starts.

    The matcher's ``check_files`` too: a network matcher opens its model, checks
    its card against the graph and runs it once on a small pair. A network on
    Triton servers none of which can be reached is an error when
    ``servers_required`` (``run --check``), else a warning: the service starts
    and its requests wait for a server (``retry_s``).

    Raises
    ------
    OSError
        A dataset root, output folder or recording folder is missing or not a folder; names the key.
    ValueError
        The matcher's model is unusable (card and graph disagree, the dry run fails), or its
        disparity range cannot fit the source's frames (:func:`check_frame_size`).
    """
    from vpp_service.sinks import SINKS
    from vpp_service.sources import SOURCES

    out = Path(cfg.service.out).expanduser()
    if out.exists() and not out.is_dir():
        raise NotADirectoryError(f"service.out: {str(out)!r} is not a folder")
    made = frozenset({out.resolve()})  # the service creates it first
    SOURCES.get(cfg.source.name).check_paths(cfg.source.options, "source", made)
    for i, spec in enumerate(cfg.sinks):
        SINKS.get(spec.name).check_paths(spec.options, f"sinks[{i}]", made)
    from vpp_service.matchers import MATCHERS, MatcherOptions

    if isinstance(cfg.matcher.options, MatcherOptions):  # a network: its model, its card, one dry run
        from vpp_service.matchers.triton import ServerUnavailable

        try:
            MATCHERS.get(cfg.matcher.name).check_files(cfg.matcher.options, "matcher")
        except ServerUnavailable as exc:
            if servers_required:
                raise
            log.warning("matcher: %s; starting anyway, requests wait for a server", exc)
    check_frame_size(cfg)


def check_frame_size(cfg: ServiceConfig) -> None:
    """Check the matcher's disparity range against the source's frame size, when the source knows it in advance.

    A fixed ``max_disparity`` must fit the frames by the matcher's own rule
    (:meth:`~vpp_service.matchers.Matcher.check_width`: below the width, after
    OpenCV's rounding to 16 for ``sgbm`` / ``bm``); ``"auto"`` needs a frame
    wider than 16 pixels. Sources whose size is known only once frames arrive
    are checked on the first frame instead (the service stops on a range that
    cannot fit it).

    Raises
    ------
    SettingsError
        ``matcher.max_disparity``: the range cannot fit; names the frame size and the range.
    """
    from vpp_service.matchers import MATCHERS, DisparityRangeError, MatcherOptions
    from vpp_service.matchers.disparity_range import round_range
    from vpp_service.sources import SOURCES

    size = SOURCES.get(cfg.source.name).frame_size(cfg.source.options)
    if size is None or not isinstance(cfg.matcher.options, MatcherOptions):
        return
    h, w = size
    where = f"the {cfg.source.name} source's {w} x {h} frames"
    if cfg.disparity_range is not None:
        try:
            round_range(cfg.disparity_range.limit, w, cfg.disparity_range.limit)
        except ValueError as exc:
            raise SettingsError(f'matcher.max_disparity: "auto" cannot fit {where}: {exc}') from None
        return
    matcher = MATCHERS.get(cfg.matcher.name)(cfg.matcher.options)
    try:
        matcher.check_width(w)
    except DisparityRangeError as exc:
        raise SettingsError(
            f"matcher.max_disparity: {matcher.options.max_disparity} cannot fit {where} ({exc}); "
            f'use a smaller max_disparity, or "auto"'
        ) from None


def read_toml(path: str | Path) -> dict[str, Any]:
    """Read a TOML config file.

    Raises
    ------
    FileNotFoundError
        The file does not exist.
    SettingsError
        The file is not valid TOML.
    """
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"config: no such file: {p}")
    try:
        return tomllib.loads(p.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise SettingsError(f"config: {p}: invalid TOML: {exc}") from None


def merge(base: Mapping[str, Any], overrides: Mapping[str, Any]) -> dict[str, Any]:
    """Deep-merge ``overrides`` into a copy of ``base`` (tables merge; other values replace)."""
    out = copy.deepcopy(dict(base))
    for k, v in overrides.items():
        if isinstance(v, Mapping) and isinstance(out.get(k), Mapping):
            out[k] = merge(out[k], v)
        else:
            out[k] = copy.deepcopy(v)
    return out


def load_config(path: str | Path | None = None, overrides: Mapping[str, Any] | None = None) -> ServiceConfig:
    """Read ``path`` (or the embedded :data:`DEFAULT_CONFIG`), apply ``overrides``, validate.

    A file replaces the default entirely (its missing sections take the
    per-section defaults, and no sinks unless it lists some).
    """
    data = read_toml(path) if path is not None else copy.deepcopy(DEFAULT_CONFIG)
    if overrides:
        data = merge(data, overrides)
    return validate_config(data)


__all__ = [
    "DEFAULT_CONFIG",
    "DEFAULT_ENDPOINT",
    "ENDPOINT_ENV",
    "SECTIONS",
    "PluginSpec",
    "QueuesSection",
    "ServiceConfig",
    "ServiceSection",
    "ZenohSection",
    "check_frame_size",
    "check_paths",
    "default_endpoint",
    "load_config",
    "merge",
    "read_toml",
    "validate_config",
]
