"""Assemble and run the service from a validated :class:`~vpp_service.service.config.ServiceConfig`.

:func:`run_service` opens the Zenoh session (``with zenoh.open(...)``), builds
the source, matcher, VPP step and sinks, runs the :class:`Pipeline` until
``max_frames``, the end of a finite source, or ``stop`` being set (the CLI sets
it on SIGINT/SIGTERM), prints a live one-line summary on stderr, and writes
``<out>/summary.json``. Shutdown is bounded by ``service.shutdown_timeout_s``.

Runtime failures never crash it: a summary.json that cannot be written (full
disk, read-only folder) is counted in ``summary_write_errors`` and logged; a
dead source ends the run with ``source_error`` set (the CLI then exits 1). A
Zenoh router that is down at start is retried in the background (peer/router
mode: the session opens at once and connects when the router appears; client
mode: opening is retried until it succeeds or the service is stopped);
``@status`` and summary.json say whether the session reaches a router.
"""

from __future__ import annotations

import contextlib
import json
import logging
import re
import sys
import threading
import time
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

from vpp_service.errors import StartupError
from vpp_service.frame import FusionResult, StereoFrame
from vpp_service.fusion import DEFAULT_DEPTH_FILTER, Fusion
from vpp_service.matchers.depth_clip import DepthClip
from vpp_service.service.allocator import reuse_freed_memory, trim_freed_memory
from vpp_service.service.config import ServiceConfig, ZenohSection
from vpp_service.service.ledger import COUNTER_NAMES, PipelineStatus
from vpp_service.service.pipeline import Pipeline
from vpp_service.sinks.folder import write_atomic

if TYPE_CHECKING:  # zenoh is imported where it is used
    import zenoh

    from vpp_service.rectify import StereoRectifier

log = logging.getLogger(__name__)


class ServiceSummary(PipelineStatus):
    """The final status :func:`run_service` returns and writes to ``<out>/summary.json``."""

    shutdown_s: float
    summary_write_errors: int
    #: Sinks that could not finish within the shutdown timeout (their outputs may be incomplete).
    unfinished_sinks: list[str]
    config: dict[str, Any]


#: The line :func:`run_service` prints once started: the text, or a function of what runs the matcher.
Banner = str | Callable[[Mapping[str, object] | None], str]

#: Reconnection to the configured endpoints (Zenoh's ``connect/retry``): first retry after 0.5 s, then at most
#: every 2 s, so outputs flow again within a few seconds after a router returns.
CONNECT_RETRY = {"period_init_ms": 500, "period_max_ms": 2000, "period_increase_factor": 2}
#: Room for Zenoh's own headers on top of ``[zenoh] max_message_mb`` of payload.
_ZENOH_HEADER_SLACK = 64 * 1024


def zenoh_config(section: ZenohSection) -> zenoh.Config:
    """A ``zenoh.Config`` from the ``[zenoh]`` section (multicast scouting off unless enabled).

    The largest message the session assembles is capped at ``max_message_mb``
    (``transport/link/rx/max_message_size``): Zenoh drops a larger one unread.
    Without a ``config_file``, the transmit queues give a ``DROP`` message
    16 batches of room, 10 ms to find one, and 250 ms for the rest of its
    fragments once it started.
    """
    import zenoh

    conf = zenoh.Config.from_file(section.config_file) if section.config_file else zenoh.Config()
    conf.insert_json5("mode", json.dumps(section.mode))
    conf.insert_json5("listen/endpoints", json.dumps(list(section.listen)))
    conf.insert_json5("connect/endpoints", json.dumps(list(section.connect)))
    conf.insert_json5("scouting/multicast/enabled", "true" if section.multicast_scouting else "false")
    max_bytes = int(section.max_message_mb * 1024 * 1024) + _ZENOH_HEADER_SLACK
    conf.insert_json5("transport/link/rx/max_message_size", str(max_bytes))
    if not section.config_file:  # a config file decides these itself
        # keep retrying unreachable endpoints in the background instead of failing the open
        conf.insert_json5("connect/timeout_ms", json.dumps({"router": -1, "peer": -1, "client": 0}))
        conf.insert_json5("connect/exit_on_failure", json.dumps({"router": False, "peer": False, "client": True}))
        conf.insert_json5("connect/retry", json.dumps(CONNECT_RETRY))
        # outputs go out with DROP (sinks.zenoh): give a busy but healthy link room and time before a
        # multi-MB map is dropped on it, while a consumer that never reads costs each put at most 10 ms
        conf.insert_json5("transport/link/tx/queue/size/data", "16")
        conf.insert_json5("transport/link/tx/queue/congestion_control/drop/wait_before_drop", "10000")
        conf.insert_json5("transport/link/tx/queue/congestion_control/drop/max_wait_before_drop_fragments", "250000")
    return conf


def zenoh_log_level(python_level: int, rust_log: str | None) -> str | None:
    """The level of Zenoh's own log for ours: ``"env"`` (``RUST_LOG`` decides), a level, or None (off).

    Zenoh's log (its Rust ``tracing`` output) cannot be handed to Python's
    ``logging``: it prints raw lines on stdout, where ``run``, ``publish`` and
    ``status`` print their JSON. So it follows our verbosity: off by default
    (what Zenoh fails at reaches us as an error that we report in our own
    words), ``info`` with ``-v``, ``debug`` with ``-vv``; ``RUST_LOG``, when
    set, is Zenoh's own switch and wins.
    """
    if rust_log:
        return "env"
    if python_level <= logging.DEBUG:
        return "debug"
    if python_level <= logging.INFO:
        return "info"
    return None


def init_zenoh_log() -> None:
    """Start Zenoh's own log at :func:`zenoh_log_level` of the root logger (Zenoh keeps the first call's)."""
    import os

    import zenoh

    level = zenoh_log_level(logging.getLogger().getEffectiveLevel(), os.environ.get("RUST_LOG"))
    if level == "env":
        zenoh.try_init_log_from_env()
    elif level is not None:
        zenoh.init_log_from_env_or(level)


def zenoh_message(exc: BaseException) -> str:
    """Zenoh's error text without its Rust source locations (`` at /path/file.rs:61.``)."""
    return re.sub(r"\s+at \S+\.rs:\d+\.?", "", str(exc)).strip() or type(exc).__name__


@contextlib.contextmanager
def zenoh_session(section: ZenohSection) -> Iterator[zenoh.Session]:
    """``with zenoh_session(section) as session``: a session configured by ``section``, ``enabled`` or not.

    For the tools that always talk to Zenoh (``publish``, ``status``); the service uses :func:`open_session`.

    Raises
    ------
    StartupError
        Zenoh could not open the session (an endpoint in use or malformed, ...), in one line.
    """
    import zenoh

    init_zenoh_log()
    try:
        session = zenoh.open(zenoh_config(section))
    except zenoh.ZError as exc:
        raise StartupError(f"zenoh: {zenoh_message(exc)}") from None
    with session:
        yield session


def has_link(session: zenoh.Session) -> bool:
    """True when ``session`` is connected to at least one router or peer (a connect endpoint replied)."""
    info = session.info
    return bool(list(info.routers_zid()) or list(info.peers_zid()))


@contextlib.contextmanager
def open_session(
    section: ZenohSection, stop: threading.Event | None = None, retry_s: float = 2.0
) -> Iterator[zenoh.Session | None]:
    """``with open_session(cfg.zenoh, stop) as session`` (None when zenoh is disabled, or ``stop`` set first).

    An open that fails because no endpoint replies (a client whose router is
    down) is retried every ``retry_s`` seconds until it succeeds or ``stop`` is set.

    Raises
    ------
    StartupError
        Any other failure to open (e.g. a listen endpoint already in use), in one line.
    """
    import zenoh

    if not section.enabled:
        yield None
        return
    stop = stop or threading.Event()
    init_zenoh_log()
    session: zenoh.Session | None = None
    while session is None:
        try:
            session = zenoh.open(zenoh_config(section))
        except zenoh.ZError as exc:
            if "Unable to connect" not in str(exc):
                raise StartupError(f"zenoh: {zenoh_message(exc)}") from None
            log.warning("zenoh: %s; retrying every %.0f s", str(exc).split(" at ", 1)[0], retry_s)
            if stop.wait(retry_s):
                yield None
                return
    with session:
        yield session


class Rectified:
    """The process step of a rig that sends raw frames: rectify (``[rectify]``), then fuse.

    A frame of the wrong size raises ``ValueError`` in the rectifier: the pipeline counts
    it as rejected and goes on.
    """

    def __init__(self, rectifier: StereoRectifier, fusion: Fusion) -> None:
        self.rectifier = rectifier
        self.fusion = fusion

    def __call__(self, frame: StereoFrame) -> FusionResult:
        """Rectify ``frame``, then :class:`~vpp_service.fusion.Fusion` on the result."""
        return self.fusion(self.rectifier(frame))

    def prepare_next(self, frame: StereoFrame) -> None:
        """The fusion step's idle-time work for the next frame."""
        self.fusion.prepare_next(frame)


def build_pipeline(cfg: ServiceConfig, session: zenoh.Session | None = None) -> Pipeline:
    """Build (not start) the pipeline described by ``cfg`` on ``session``."""
    from vpp_service.matchers import MATCHERS, MatcherOptions
    from vpp_service.sinks.base import SINKS, SinkContext
    from vpp_service.sources.base import SOURCES, SourceContext

    s = cfg.service
    source = SOURCES.get(cfg.source.name)(
        cfg.source.options, SourceContext(rig=s.rig, prefix=s.prefix, session=session)
    )
    sink_ctx = SinkContext(rig=s.rig, prefix=s.prefix, session=session)
    sinks = [SINKS.get(sp.name)(sp.options, sink_ctx) for sp in cfg.sinks]
    options = cfg.matcher.options  # validated, with max_disparity "auto" taken off (cfg.disparity_range)
    if not isinstance(options, MatcherOptions):
        raise TypeError(f"matcher options must be MatcherOptions, got {type(options).__name__}")
    matcher = MATCHERS.get(cfg.matcher.name)(options)
    # metric depth is computed only when a sink reads it (each sink says so)
    needs_depth = any(SINKS.get(sp.name).needs_depth(sp.options) for sp in cfg.sinks)
    # so is the confidence (for most matchers a second matching pass)
    needs_confidence = any(SINKS.get(sp.name).needs_confidence(sp.options) for sp in cfg.sinks)
    fusion = Fusion(
        matcher,
        cfg.vpp,
        seed=s.seed,
        depth=needs_depth,
        disparity_range=cfg.disparity_range,
        depth_filter=cfg.depth_filter if cfg.depth_filter is not None else DEFAULT_DEPTH_FILTER,
        depth_clip=cfg.depth_clip or DepthClip(),  # one valid depth range for every output
        confidence=needs_confidence,
    )
    process: Callable[[StereoFrame], FusionResult] = fusion
    if cfg.rectify is not None:  # the rig sends raw frames: rectify them first (maps computed once, here)
        process = Rectified(cfg.rectify.build(), fusion)
    q = cfg.queues
    return Pipeline(
        source,
        process,
        sinks,
        input_size=q.input_size,
        input_policy=q.input_policy,
        output_size=q.output_size,
        output_policy=q.output_policy,
        max_frames=s.max_frames,
        session=session,
        prefix=s.prefix,
        rig=s.rig,
        timing_window=s.timing_window,
        reject_log_period_s=s.reject_log_period_s,
        in_flight=int(getattr(options, "in_flight", 1)),  # a network on Triton servers: frames matched at once
    )


def run_service(
    cfg: ServiceConfig,
    stop: threading.Event | None = None,
    stream: TextIO | None = sys.stderr,
    banner: Banner | None = None,
) -> ServiceSummary:
    """Run until done or ``stop`` is set; return the final status (also in ``<out>/summary.json``).

    Parameters
    ----------
    cfg : ServiceConfig
        Validated configuration.
    stop : threading.Event or None
        Set it to stop (signal handlers do).
    stream : text stream or None
        Where the live summary goes (None = nowhere): on a terminal one line rewritten every
        ``summary_period_s``; otherwise a new line only when the counters changed.
    banner : str, callable or None
        Printed on ``stream`` once everything has started; a callable gets what
        runs the matcher (:attr:`Pipeline.matcher_runtime`) and returns the text.
    """
    stop = stop or threading.Event()
    s = cfg.service
    out = Path(s.out)
    created = not out.exists()
    out.mkdir(parents=True, exist_ok=True)
    try:
        return _run(cfg, stop, stream, banner, out)
    except BaseException:
        if created:  # a failed start leaves nothing behind (rmdir removes only an empty folder)
            with contextlib.suppress(OSError):
                out.rmdir()
        raise


def _run(
    cfg: ServiceConfig, stop: threading.Event, stream: TextIO | None, banner: Banner | None, out: Path
) -> ServiceSummary:
    """:func:`run_service` once ``out`` exists."""
    s = cfg.service
    summary_path = out / "summary.json"
    if s.reuse_memory:
        reuse_freed_memory()
    write_errors = [0]
    _quiet_opencv()
    with open_session(cfg.zenoh, stop) as session:
        if session is None and cfg.zenoh.enabled:  # stopped while waiting for the router: nothing ran
            return _not_started(cfg)
        pipe = build_pipeline(cfg, session)
        pipe.start()
        linked: bool | None = None
        if session is not None:
            log.info("zenoh session %s listening on %s", session.info.zid(), list(cfg.zenoh.listen))
        if banner and stream is not None:
            print(banner(pipe.matcher_runtime) if callable(banner) else banner, file=stream, flush=True)
        tty = bool(getattr(stream, "isatty", lambda: False)())
        last_counters: dict[str, int] | None = None
        try:
            next_report = time.monotonic() + s.summary_period_s
            trim = _TrimAfterRejects()
            while not stop.is_set() and not pipe.done.is_set():
                stop.wait(0.1)
                link = pipe.connectivity() if cfg.zenoh.connect else None
                if link is not None:
                    linked = _log_link(link, linked, cfg.zenoh.connect)
                trim.poll(pipe.rejected)  # polled every 0.1 s: not the whole status
                if time.monotonic() >= next_report:
                    next_report += s.summary_period_s
                    st = pipe.status()  # once per report: it costs about a millisecond of the matcher's CPU
                    counters = st["counters"]
                    # a terminal gets a live line; a log (journal, file) only a line when something changed
                    if s.summary and stream is not None and (tty or counters != last_counters):
                        print(
                            ("\r" if tty else "") + pipe.summary_line(st),
                            end="" if tty else "\n",
                            file=stream,
                            flush=True,
                        )
                    last_counters = counters
                    _write_json(summary_path, {**st, "summary_write_errors": write_errors[0]}, write_errors)
        finally:
            t0 = time.monotonic()
            pipe.stop(s.shutdown_timeout_s)
            status: ServiceSummary = {
                **pipe.status(),
                "shutdown_s": time.monotonic() - t0,
                "summary_write_errors": write_errors[0],
                "unfinished_sinks": list(pipe.unfinished_sinks),
                "config": cfg.to_dict(),
            }
            if not _write_json(summary_path, status, write_errors):
                status["summary_write_errors"] = write_errors[0]
            if s.summary and stream is not None:
                print(("\r" if tty else "") + pipe.summary_line(), file=stream, flush=True)
    return status


class _TrimAfterRejects:
    """Hand freed memory back after rejected input (which may have been large): :func:`trim_freed_memory`.

    Polled with the ``rejected`` counter: trims once the counter has been still
    for ``quiet_s`` (the rejected message is freed by then), and at most every
    ``period_s`` while rejects keep coming.
    """

    def __init__(self, quiet_s: float = 0.3, period_s: float = 1.0) -> None:
        self.quiet_s, self.period_s = quiet_s, period_s
        self._seen = 0
        self._due = False
        self._changed = self._next = 0.0

    def poll(self, rejected: int) -> None:
        """Look at the ``rejected`` counter; trim when due."""
        now = time.monotonic()
        if rejected != self._seen:
            self._seen, self._due, self._changed = rejected, True, now
        if self._due and (now - self._changed >= self.quiet_s or now >= self._next):
            self._due, self._next = False, now + self.period_s
            trim_freed_memory()


def _quiet_opencv() -> None:
    """Keep OpenCV's own warnings (e.g. about a stream it cannot decode) out of the log.

    A bad image in a message is rejected with its reason through the pipeline's
    rate-limited reject log; a line per hostile message from OpenCV would bypass it.
    """
    import cv2

    logging_mod = getattr(getattr(cv2, "utils", None), "logging", None)
    if logging_mod is not None:
        logging_mod.setLogLevel(logging_mod.LOG_LEVEL_ERROR)


def _write_json(path: Path, data: Mapping[str, object], errors: list[int]) -> bool:
    """Write ``data`` atomically; a failure (full disk, read-only folder) is counted in ``errors[0]`` and logged."""
    try:
        write_atomic(path, json.dumps(data, indent=2, default=str).encode(), overwrite=True)
    except OSError as exc:
        errors[0] += 1
        if errors[0] == 1 or errors[0] % 100 == 0:
            log.error("writing %s failed (%d failures so far): %s", path, errors[0], exc)
        return False
    return True


def _log_link(now: Mapping[str, int], linked: bool | None, endpoints: list[str]) -> bool:
    """Log when the session gains or loses its connected endpoints; returns whether any is connected."""
    up = now["routers"] + now["peers"] > 0
    if up != linked:
        if up:
            log.info("zenoh: connected (%d router(s), %d peer(s))", now["routers"], now["peers"])
        else:
            log.warning("zenoh: not connected to %s; retrying in the background", ", ".join(endpoints))
    return up


def _not_started(cfg: ServiceConfig) -> ServiceSummary:
    """The summary of a run stopped before its Zenoh session could open."""
    empty = {**dict.fromkeys(COUNTER_NAMES, 0), "dropped": 0}
    return {
        "rig": cfg.service.rig,
        "prefix": cfg.service.prefix,
        "uptime_s": 0.0,
        "counters": empty,
        "dropped": {},
        "source_error": None,
        "config_error": None,
        "zenoh": {"routers": 0, "peers": 0},
        "fps": 0.0,
        "queues": {},
        "timing_ms": {},
        "status_queries": {"queries": 0, "snapshots": 0, "cached": 0},
        "source": {},
        "sinks": {},
        "metrics": {"last": {}, "bad2_answered_mean": None, "density_mean": None, "bad2_filled_mean": None},
        "shutdown_s": 0.0,
        "summary_write_errors": 0,
        "unfinished_sinks": [],
        "config": cfg.to_dict(),
    }


__all__ = [
    "Banner",
    "ServiceSummary",
    "build_pipeline",
    "init_zenoh_log",
    "open_session",
    "run_service",
    "zenoh_config",
    "zenoh_log_level",
    "zenoh_message",
    "zenoh_session",
]
