"""Frame sources (Zenoh, files, simulator) and the depth-sensor / synthetic-scene simulators.

Importing this package registers the built-in sources in :data:`SOURCES`
(``zenoh``, ``ros2``, ``rosbag2``, ``files``, ``sim``); see :mod:`.base` for the plugin interface.
"""

from vpp_service.sources import files, ros2, rosbag2, sim, zenoh  # noqa: F401 - registration side effects
from vpp_service.sources.base import SOURCES, Source, SourceContext, build_source, parse_source_options

__all__ = ["SOURCES", "Source", "SourceContext", "build_source", "parse_source_options"]
