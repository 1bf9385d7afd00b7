"""The frame-source plugin interface and registry.

A source produces :class:`~vpp_service.frame.StereoFrame` objects for the
pipeline. Life cycle, mirroring :mod:`vpp_service.sinks.base`:

1. ``cls.Options`` -- a frozen dataclass of the source's options, validated with
   :func:`vpp_service.settings.from_mapping` before anything opens.
2. ``src = cls(options, context)`` then ``src.open()`` -- acquire resources
   (files, Zenoh subscribers, the simulator's scene).
3. ``src.start(emit, reject)`` -- start producing from the source's own thread:
   ``emit(frame)`` hands over a frame (the pipeline's queue policy decides what
   happens when it is full), ``reject(reason)`` reports a bad input message,
   which the pipeline counts and logs (rate-limited). When a finite source has
   nothing left it sets :attr:`Source.finished` and calls ``on_finished()`` when given.
   An exception escaping :meth:`Source.run` is fatal: it is logged, kept in
   :attr:`Source.error`, and the source finishes (the service then exits non-zero).
4. ``src.stop(timeout)`` -- stop producing and release, within ``timeout`` seconds.

``src.stats()`` returns counters (``emitted``, ``rejected`` and extras) for ``@status``;
``src.losses()`` the valid input the source itself lost, by cause (the pipeline
adds them to its one ``dropped`` count). ``src.input_policy`` is the pipeline's
input policy, set before ``open``: under ``block`` a source that buffers must
hold its producer back rather than drop.
"""

from __future__ import annotations

import logging
import threading
from abc import abstractmethod
from collections.abc import Callable, Mapping
from typing import Any, ClassVar

from vpp_service.frame import StereoFrame
from vpp_service.plugin import Plugin, PluginContext, parse_plugin_options
from vpp_service.queueing import Policy
from vpp_service.registry import Registry

log = logging.getLogger(__name__)

#: Registered source classes by name ("zenoh", "files", "sim").
SOURCES: Registry[Source] = Registry("source")

#: ``emit(frame)`` callback type; returns False when the frame was dropped.
Emit = Callable[[StereoFrame], bool]
#: ``reject(reason)`` callback type.
Reject = Callable[[str], None]


class SourceContext(PluginContext):
    """Service-wide facts a source may need (fields: see :class:`~vpp_service.plugin.PluginContext`)."""


class Source(Plugin):
    """Base class of frame sources (see the module docstring for the life cycle).

    Parameters
    ----------
    options : object
        Instance of the subclass's ``Options`` (each subclass narrows the type).
    context : SourceContext
        Service-wide facts.
    """

    counter_names = ("emitted", "rejected")
    #: True for a source that replays recorded data (a folder, a recording, a bag): nothing in the world is
    #: lost by making it wait, so the service back-pressures it by default (``block`` queues end to end) and
    #: loses no frame unless the config asks for ``latest``. False (the default) for a live source.
    finite: ClassVar[bool] = False
    #: True for a source that takes frames from the network (a camera publishing on Zenoh or ROS 2): a
    #: long-running service, so by default (``service.resume = "auto"``) a restart resumes in its output
    #: folder (the previous ``summary.json`` rotated) instead of refusing to start over a previous run.
    network: ClassVar[bool] = False

    @classmethod
    def frame_size(cls, options: Any) -> tuple[int, int] | None:
        """``(height, width)`` of every frame this source will emit, when the options alone tell it.

        ``run --check`` checks the matcher's disparity range against it. None
        (the default) when it is known only once frames arrive (a camera, a
        recording, a dataset of several sizes).
        """
        return None

    def __init__(self, options: object, context: SourceContext) -> None:
        super().__init__(options, context)
        #: The exception that ended :meth:`run` (a dead source), None while healthy or after a clean end.
        self.error: BaseException | None = None
        #: The pipeline's input policy (set before :meth:`open`): ``block`` asks for back-pressure, not drops.
        self.input_policy: Policy = "latest"
        #: Set when a finite source has produced its last frame.
        self.finished = threading.Event()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self, emit: Emit, reject: Reject | None = None, on_finished: Callable[[], None] | None = None) -> None:
        """Start producing frames from a daemon thread running :meth:`run`.

        Parameters
        ----------
        emit : callable
            ``emit(frame)``: hands a frame over.
        reject : callable or None
            ``reject(reason)``: reports a bad input message.
        on_finished : callable or None
            Called on the source's thread once :meth:`run` has returned (after
            :attr:`finished` is set): the consumer learns that no frame follows.
        """
        if self._thread is not None:
            raise RuntimeError("source already started")
        reject = reject or (lambda reason: None)

        def body() -> None:
            try:
                self.run(emit, reject)
            except Exception as exc:  # kept for the service's exit code, not lost with the thread
                self.error = exc
                log.exception("source %s failed", type(self).__name__)
            finally:
                self.finished.set()
                if on_finished is not None:
                    on_finished()

        self._stop.clear()
        self._thread = threading.Thread(target=body, name=f"source-{type(self).__name__}", daemon=True)
        self._thread.start()

    @abstractmethod
    def run(self, emit: Emit, reject: Reject) -> None:
        """Produce frames until :meth:`stopping` or the source is exhausted."""

    def stopping(self) -> bool:
        """True once :meth:`stop` was called."""
        return self._stop.is_set()

    def wait(self, seconds: float) -> bool:
        """Sleep up to ``seconds``; returns True when asked to stop meanwhile."""
        return self._stop.wait(seconds)

    def request_stop(self) -> None:
        """Ask the producing thread to stop, without waiting (safe from any thread)."""
        self._stop.set()

    def stop(self, timeout: float = 5.0) -> None:
        """Stop producing and join the thread within ``timeout`` seconds."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout)
        self.close()

    def close(self) -> None:
        """Release resources (called by :meth:`stop`)."""

    def losses(self) -> dict[str, int]:
        """Valid input this source lost before emitting it, by cause (none by default)."""
        return {}

    def waits_on(self) -> str:
        """What this source takes frames from, for the live line while nothing has arrived (e.g. a key expression)."""
        return f"the {type(self).__name__}"


def parse_source_options(name: str, options: Mapping[str, Any] | None, section: str | None = None) -> object:
    """Validate ``options`` for source ``name`` without building it."""
    return parse_plugin_options(SOURCES, name, options, section or f"source.{name}")


def build_source(name: str, options: Mapping[str, Any] | None = None, context: SourceContext | None = None) -> Source:
    """Build (not open) the source registered as ``name`` from a plain options mapping."""
    cls = SOURCES.get(name)
    return cls(parse_source_options(name, options), context or SourceContext())


__all__ = ["SOURCES", "Emit", "Reject", "Source", "SourceContext", "build_source", "parse_source_options"]


class Pacer:
    """Release frames at ``rate_hz`` (0 = as fast as possible) without drift.

    Parameters
    ----------
    rate_hz : float
        Target rate; 0 disables pacing.
    """

    def __init__(self, rate_hz: float) -> None:
        if not rate_hz >= 0:
            raise ValueError(f"rate_hz must be >= 0, got {rate_hz!r}")
        self.period = 1.0 / rate_hz if rate_hz > 0 else 0.0
        self._next: float | None = None

    def wait(self, source: Source) -> bool:
        """Sleep until the next slot; True when ``source`` was asked to stop meanwhile."""
        import time

        if self.period == 0:
            return source.stopping()
        now = time.monotonic()
        if self._next is None:
            self._next = now
        delay = self._next - now
        self._next = max(self._next + self.period, now - self.period)  # no burst after a stall
        return source.wait(delay) if delay > 0 else source.stopping()


__all__ += ["Pacer"]
