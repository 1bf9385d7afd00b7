"""Result sinks, registered by name in :data:`SINKS` (see :mod:`.base`)."""
from vpp_service.sinks.base import SINKS, Sink, build_sink

__all__ = ["SINKS", "Sink", "build_sink"]
