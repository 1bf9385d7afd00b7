"""Frame sources (Zenoh, files, simulator) and the depth-sensor / synthetic-scene simulators.

Importing this package registers the built-in sources in :data:`SOURCES`
(``zenoh``, ``files``, ``sim``); see :mod:`.base` for the plugin interface.
"""
from vpp_service.sources.base import SOURCES, Source, SourceContext, build_source, parse_source_options
from vpp_service.sources import files, sim, zenoh  # noqa: F401,E402 - registration side effects

__all__ = ["SOURCES", "Source", "SourceContext", "build_source", "parse_source_options"]
