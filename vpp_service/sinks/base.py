"""The sink plugin interface and registry.

A sink receives every :class:`~vpp_service.frame.FusionResult` the pipeline
produces. The pipeline calls, in order:

1. ``cls.Options`` -- a frozen dataclass of the sink's options; the whole
   service config is parsed with ``cls.parse_options`` (the dataclass, then the
   sink's own :meth:`~vpp_service.plugin.Plugin.check_options`) before anything
   opens, so a bad key fails the start, not frame 1000. ``cls.needs_depth(options)``
   tells the service whether to compute metric depth for this sink.
2. ``sink = cls(options, context)`` then ``sink.open()`` -- acquire resources.
3. The pipeline owns every buffer: it gives each sink its own bounded queue and
   thread, sized by ``sink.queue_spec()`` (a :class:`QueueSpec`: size, and
   ``block`` for a sink that must never drop, such as a recording; otherwise the
   ``[queues]`` output policy decides, and a full queue drops its oldest result,
   counted as the sink's loss). On that thread it calls ``sink.start()`` once,
   then ``sink.write(result)`` once per frame -- plain and synchronous --, then
   ``sink.finish()`` after the last one. A slow consumer (a Rerun viewer, the
   network) delays only its own sink's thread.
4. ``sink.close(timeout)`` -- release within ``timeout`` seconds, even when a
   peer or viewer is gone (the pipeline abandons a close that does not return).

``sink.stats()`` returns counters (``written``, ``dropped``, ``errors``) that
the service reports in its ``@status`` reply.
"""

from __future__ import annotations

from abc import abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Annotated, Any, Literal

from vpp_service.frame import FusionResult
from vpp_service.plugin import Plugin, PluginContext, parse_plugin_options
from vpp_service.registry import Registry
from vpp_service.settings import Options, Range

#: Registered sink classes by name ("zenoh", "rerun", "files").
SINKS: Registry[Sink] = Registry("sink")


class SinkContext(PluginContext):
    """Service-wide facts a sink may need (fields: see :class:`~vpp_service.plugin.PluginContext`)."""


@dataclass(frozen=True)
class QueueSpec(Options):
    """How the pipeline buffers results for one sink (:meth:`Sink.queue_spec`).

    Attributes
    ----------
    size : int or None
        Results waiting for the sink; None: ``[queues] output_size``.
    policy : {"block"} or None
        ``"block"``: the sink never drops (a recording): a full queue makes the
        pipeline wait. None: the ``[queues]`` output policy decides (``latest``
        drops the oldest result when full, counted; ``block`` waits).
    """

    size: Annotated[int | None, Range(1)] = None
    policy: Literal["block"] | None = None


class Sink(Plugin):
    """Base class of result sinks (see the module docstring for the life cycle).

    Parameters
    ----------
    options : object
        Instance of the subclass's ``Options`` (each subclass narrows the type).
    context : SinkContext
        Service-wide facts.
    """

    counter_names = ("written", "dropped", "errors")

    def queue_spec(self) -> QueueSpec:
        """How the pipeline buffers results for this sink (default: the ``[queues]`` output settings)."""
        return QueueSpec()

    def start(self) -> None:
        """On the sink's thread, before the first :meth:`write` (attach to a viewer, create a file)."""

    def finish(self) -> None:
        """On the sink's thread, after the last :meth:`write` (flush, close a file)."""

    @classmethod
    def needs_depth(cls, options: Any) -> bool:
        """Whether this sink, with these options, reads ``FusionResult.depth``.

        The service computes metric depth only when some sink does. The default
        (True) is safe for a sink that may read it; sinks that never do say so.

        Parameters
        ----------
        options : Any
            The parsed ``Options`` instance.
        """
        return True

    @classmethod
    def needs_confidence(cls, options: Any) -> bool:
        """Whether this sink, with these options, reads ``FusionResult.confidence``.

        The service computes the per-pixel confidence only when some sink does
        (for matchers other than census-sgm it costs a second matching pass). The
        default is False: only sinks with a ``confidence`` output say True.

        Parameters
        ----------
        options : Any
            The parsed ``Options`` instance.
        """
        return False

    @abstractmethod
    def write(self, result: FusionResult) -> None:
        """Consume one result, synchronously (on the sink's own thread when the pipeline drives it)."""

    def close(self, timeout: float = 5.0) -> None:
        """Flush and release resources within ``timeout`` seconds."""

    def __enter__(self) -> Sink:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def parse_sink_options(name: str, options: Mapping[str, Any] | None, section: str | None = None) -> object:
    """Validate ``options`` for sink ``name`` without building it."""
    return parse_plugin_options(SINKS, name, options, section or f"sinks.{name}")


def build_sink(name: str, options: Mapping[str, Any] | None = None, context: SinkContext | None = None) -> Sink:
    """Build (not open) the sink registered as ``name`` from a plain options mapping."""
    cls = SINKS.get(name)
    return cls(parse_sink_options(name, options), context or SinkContext())
