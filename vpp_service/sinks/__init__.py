"""Result sinks, registered by name in :data:`SINKS` (see :mod:`.base`)."""

from vpp_service.sinks import files as _files  # noqa: F401 - registers "files"
from vpp_service.sinks import record as _record  # noqa: F401 - registers "record"
from vpp_service.sinks import rerun as _rerun  # noqa: F401 - registers "rerun"
from vpp_service.sinks import ros2 as _ros2  # noqa: F401 - registers "ros2"
from vpp_service.sinks import rosbag2 as _rosbag2  # noqa: F401 - registers "rosbag2"
from vpp_service.sinks import zenoh as _zenoh  # noqa: F401 - registers "zenoh"
from vpp_service.sinks.base import SINKS, Sink, build_sink

__all__ = ["SINKS", "Sink", "build_sink"]
