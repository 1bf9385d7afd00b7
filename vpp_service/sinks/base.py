"""The sink plugin interface and registry.

A sink receives every :class:`~vpp_service.frame.FusionResult` the pipeline
produces. The pipeline calls, in order:

1. ``cls.Options`` -- a frozen dataclass of the sink's options; the whole
   service config is parsed with ``cls.parse_options`` (the dataclass, then the
   sink's own :meth:`~vpp_service.plugin.Plugin.check_options`) before anything
   opens, so a bad key fails the start, not frame 1000. ``cls.needs_depth(options)``
   tells the service whether to compute metric depth for this sink.
2. ``sink = cls(options, context)`` then ``sink.open()`` -- acquire resources.
3. ``sink.write(result)`` from the pipeline's sink thread, once per frame. It
   must not block for long: a slow consumer (a Rerun viewer, the network) is
   decoupled inside the sink (own thread + bounded queue) and drops are counted.
   ``sink.queue_policy`` is the pipeline's output policy, set before ``open``:
   under ``block`` (a replay) a sink that buffers makes ``write`` wait for room
   rather than drop.
4. ``sink.close(timeout)`` -- flush and release within ``timeout`` seconds,
   even when a peer or viewer is gone.

``sink.stats()`` returns counters (``written``, ``dropped``, ``errors``) that
the service reports in its ``@status`` reply.
"""

from __future__ import annotations

from abc import abstractmethod
from collections.abc import Mapping
from typing import Any, ClassVar

from vpp_service.frame import FusionResult
from vpp_service.plugin import Plugin, PluginContext, parse_plugin_options
from vpp_service.queueing import Policy
from vpp_service.registry import Registry

#: Registered sink classes by name ("zenoh", "rerun", "files").
SINKS: Registry[Sink] = Registry("sink")


class SinkContext(PluginContext):
    """Service-wide facts a sink may need (fields: see :class:`~vpp_service.plugin.PluginContext`)."""


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
    #: True for a sink whose ``write`` puts the frame's outputs on the network: in a worker pool the
    #: frame counts as answered once this sink has written it (it calls ``context.extra["on_written"]``
    #: with the ``seq``); without such a sink the pipeline announces a frame when every sink is done.
    answers_pool: ClassVar[bool] = False

    def __init__(self, options: Any, context: SinkContext) -> None:
        super().__init__(options, context)
        #: The pipeline's output policy (set before :meth:`open`): ``block`` asks a buffering sink to wait, not drop.
        self.queue_policy: Policy = "latest"

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

    @abstractmethod
    def write(self, result: FusionResult) -> None:
        """Consume one result; never blocks indefinitely."""

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
