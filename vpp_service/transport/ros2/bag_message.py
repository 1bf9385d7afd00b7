"""One recorded message of a rosbag2 bag, as every bag reader yields it.

Its own module, below :mod:`~vpp_service.transport.ros2.bag` (which picks a reader) and the readers
(:mod:`~vpp_service.transport.ros2.db3_reader`, :mod:`~vpp_service.transport.ros2.mcap_reader`), so that
the readers need not import the module that imports them.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class BagMessage:
    """One recorded message.

    Attributes
    ----------
    topic : str
        Fully-qualified topic name.
    ros_type : str
        ``pkg/msg/Msg``.
    log_time_ns : int
        Recording time of the message, ns.
    data : bytes
        The CDR payload.
    """

    topic: str
    ros_type: str
    log_time_ns: int
    data: bytes


__all__ = ["BagMessage"]
