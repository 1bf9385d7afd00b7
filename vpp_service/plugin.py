"""What sources and sinks share: the service context, the options/counters base and option parsing.

Sources (:mod:`vpp_service.sources.base`) and sinks (:mod:`vpp_service.sinks.base`)
are plugins with the same shape: a frozen ``Options`` dataclass validated with
:func:`vpp_service.settings.from_mapping` before anything opens, a constructor
``cls(options, context)``, an optional :meth:`Plugin.open` hook and counters
reported by :meth:`Plugin.stats`. This module holds that shape once; each base
module adds its own life-cycle methods (``write``/``close`` or ``start``/``stop``).

Each plugin validates its own options (CNES Pandora's ``check_conf`` idea):
:meth:`Plugin.parse_options` checks types and ranges (the dataclass) and then
calls the plugin's :meth:`Plugin.check_options` hook for what the dataclass
cannot check alone (e.g. the simulator source builds its sensor). What the
service must know about a plugin it asks the plugin (:attr:`Plugin.needs_session`,
``Sink.needs_depth``), so the service never reads a plugin's option names.
"""

from __future__ import annotations

import threading
from abc import ABC
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar, TypeVar

from vpp_service.registry import Registry
from vpp_service.settings import from_mapping

if TYPE_CHECKING:  # zenoh is imported where it is used
    import zenoh
    from _typeshed import DataclassInstance


@dataclass
class PluginContext:
    """Service-wide facts a source or sink may need.

    Attributes
    ----------
    rig : str
        Rig name (topic names, entity paths; frames get this rig unless the wire says otherwise).
    prefix : str
        Zenoh key prefix (default ``"vpp"``).
    session : zenoh.Session or None
        The service's open Zenoh session when one exists, else None.
    extra : dict
        Free-form extras.
    """

    rig: str = "rig0"
    prefix: str = "vpp"
    session: zenoh.Session | None = None
    extra: dict[str, object] = field(default_factory=dict)


class Plugin(ABC):
    """Base of sources and sinks: keeps ``options`` and ``context``, owns the counters.

    Parameters
    ----------
    options : Any
        Instance of the subclass's ``Options`` (already validated).
    context : PluginContext
        Service-wide facts.
    """

    #: Frozen dataclass describing the options; every concrete plugin sets it.
    Options: ClassVar[type[DataclassInstance]]
    #: Counters every instance starts at 0 (subclasses may add more in ``__init__``).
    counter_names: ClassVar[tuple[str, ...]] = ()
    #: True when the plugin needs the service's Zenoh session (``context.session``);
    #: the config is rejected when such a plugin is chosen with ``zenoh.enabled = false``.
    needs_session: ClassVar[bool] = False

    @classmethod
    def parse_options(cls, options: Mapping[str, Any] | None, section: str) -> Any:
        """Build and check this plugin's ``Options`` from a plain mapping.

        Parameters
        ----------
        options : Mapping or None
            Plain option values; None means all defaults.
        section : str
            Config section named in error messages (e.g. ``"source"``, ``"sinks[0]"``).

        Returns
        -------
        Any
            The ``Options`` instance, checked by the dataclass and by :meth:`check_options`.

        Raises
        ------
        SettingsError
            Unknown key, wrong type, out-of-range value or a failed plugin check;
            the message starts with ``section`` or ``section.key``.
        """
        parsed: Any = from_mapping(cls.Options, options or {}, section)
        cls.check_options(parsed, section)
        return parsed

    @classmethod  # noqa: B027 - optional hook, a no-op by default
    def check_options(cls, options: Any, section: str) -> None:
        """Check what the ``Options`` dataclass cannot check alone; nothing by default.

        Runs when the config is validated, before anything opens. Override it to
        raise :class:`~vpp_service.settings.SettingsError` naming ``section.key``.

        Parameters
        ----------
        options : Any
            The parsed ``Options`` instance.
        section : str
            Config section of this plugin (prefix of error messages).
        """

    @classmethod  # noqa: B027 - optional hook, a no-op by default
    def check_paths(cls, options: Any, section: str, created_dirs: frozenset[Path] = frozenset()) -> None:
        """Check the files and folders the options name; nothing by default.

        Runs for ``vpp-service run --check`` and before the service opens anything
        (validation itself never touches the file system).

        Parameters
        ----------
        options : Any
            The parsed ``Options`` instance.
        section : str
            Config section of this plugin (prefix of error messages).
        created_dirs : frozenset of Path
            Folders the service creates before it opens the plugins (they count as existing).

        Raises
        ------
        OSError
            A path is missing or of the wrong kind; the message names ``section.key``.
        """

    def __init__(self, options: Any, context: PluginContext) -> None:
        self.options = options
        self.context = context
        self._counters: dict[str, int] = dict.fromkeys(self.counter_names, 0)
        self._counters_lock = threading.Lock()

    def open(self) -> None:  # noqa: B027 - optional hook
        """Acquire resources (files, sessions, threads)."""

    def count(self, name: str, n: int = 1) -> None:
        """Add ``n`` to counter ``name`` under the counters' one lock (safe from any thread)."""
        with self._counters_lock:
            self._counters[name] = self._counters.get(name, 0) + n

    def stats(self) -> dict[str, int]:
        """A copy of the counters (see ``counter_names``; subclasses may add extras)."""
        with self._counters_lock:
            return dict(self._counters)


P = TypeVar("P", bound=Plugin)


def parse_plugin_options(registry: Registry[P], name: str, options: Mapping[str, Any] | None, section: str) -> Any:
    """Validate ``options`` for the plugin registered as ``name`` in ``registry``.

    Parameters
    ----------
    registry : Registry of Plugin subclasses
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
        The plugin's ``Options`` instance (see :meth:`Plugin.parse_options`).
    """
    # The registry's type is not enforced at run time: check what was registered before calling it.
    cls: object = registry.get(name)
    if not (isinstance(cls, type) and issubclass(cls, Plugin)):
        raise TypeError(f"{registry.kind} {name!r} is registered as {cls!r}, not as a Plugin class")
    return cls.parse_options(options, section)


__all__ = ["Plugin", "PluginContext", "parse_plugin_options"]
