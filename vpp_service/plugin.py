"""What sources and sinks share: the service context, the options/counters base and option parsing.

Sources (:mod:`vpp_service.sources.base`) and sinks (:mod:`vpp_service.sinks.base`)
are plugins with the same shape: a frozen ``Options`` dataclass validated with
:func:`vpp_service.settings.from_mapping` before anything opens, a constructor
``cls(options, context)``, an optional :meth:`Plugin.open` hook and counters
reported by :meth:`Plugin.stats`. This module holds that shape once; each base
module adds its own life-cycle methods (``write``/``close`` or ``start``/``stop``).
"""
from __future__ import annotations

from abc import ABC
from dataclasses import dataclass, field
from typing import Any, ClassVar, Mapping

from vpp_service.registry import Registry
from vpp_service.settings import from_mapping


@dataclass
class PluginContext:
    """Service-wide facts a source or sink may need.

    Attributes
    ----------
    rig : str
        Rig name (topic names, entity paths; frames get this rig unless the wire says otherwise).
    prefix : str
        Zenoh key prefix (default ``"vpp"``).
    session : Any
        The service's open ``zenoh.Session`` when one exists, else None.
    extra : dict
        Free-form extras.
    """

    rig: str = "rig0"
    prefix: str = "vpp"
    session: Any = None
    extra: dict[str, Any] = field(default_factory=dict)


class Plugin(ABC):
    """Base of sources and sinks: keeps ``options`` and ``context``, owns the counters.

    Parameters
    ----------
    options : Any
        Instance of the subclass's ``Options`` (already validated).
    context : PluginContext
        Service-wide facts.
    """

    #: Frozen dataclass describing the options; override in subclasses.
    Options: ClassVar[type] = None  # type: ignore[assignment]
    #: Counters every instance starts at 0 (subclasses may add more in ``__init__``).
    counter_names: ClassVar[tuple[str, ...]] = ()

    def __init__(self, options: Any, context: PluginContext) -> None:
        self.options = options
        self.context = context
        self._counters: dict[str, int] = dict.fromkeys(self.counter_names, 0)

    def open(self) -> None:  # noqa: B027 - optional hook
        """Acquire resources (files, sessions, threads)."""

    def stats(self) -> dict[str, int]:
        """A copy of the counters (see ``counter_names``; subclasses may add extras)."""
        return dict(self._counters)


def parse_plugin_options(registry: Registry, name: str, options: Mapping[str, Any] | None, section: str) -> Any:
    """Validate ``options`` for the plugin registered as ``name`` in ``registry``.

    Parameters
    ----------
    registry : Registry
        ``SOURCES`` or ``SINKS``.
    name : str
        Registered plugin name (unknown names raise ValueError listing the known ones).
    options : Mapping or None
        Plain option values; None means all defaults.
    section : str
        Config section named in error messages (e.g. ``"sinks.files"``).

    Returns
    -------
    Any
        The plugin's ``Options`` instance.
    """
    cls = registry.get(name)
    return from_mapping(cls.Options, options or {}, section)


__all__ = ["PluginContext", "Plugin", "parse_plugin_options"]
