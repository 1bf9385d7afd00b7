"""ROS 2 source: subscribe to a stereo rig's topics as an ``rmw_zenoh`` node does.

Under ``namespace`` (default ``/stereo``) and ``domain_id`` (default 0) it subscribes
to ``left/image_rect``, ``left/camera_info``, ``right/image_rect``, ``right/camera_info``
and the sparse depth on ``points`` (a ``PointCloud2``, or with ``depth_type = "image"``
a depth ``Image`` registered to the left camera), and, for a cloud without a configured
``lidar_to_left``, the static transforms on ``/tf_static``; every name is an option, and an
absolute name (``/velodyne_points``) ignores the namespace. With ``transport = "compressed"``
the views are ``sensor_msgs/CompressedImage`` on ``<image topic>/compressed``; with
``rectify = true`` they are raw images, rectified with their camera_info. It declares a node token
and one subscriber token per topic, so lazy publishers start sending. The tokens carry
``ros_distro``'s type-hash segment (``humble``: ``TypeHashNotSupported``) and the QoS the
source keeps: best effort, volatile, depth ``ring_size``, keep last under the ``latest``
input policy and keep all under ``block``. Publishers of any type hash are received.

The Zenoh callback checks each sample's size (``max_message_mb``) and attachment
(both rmw_zenoh layouts accepted), refusing a failed one before it takes a ring slot,
and queues the others in their topic's ring (the network sources' shared part,
:class:`~vpp_service.sources.network.NetworkSource`, ``ring_size`` per topic): under
the pipeline's ``latest`` input policy a full ring drops its oldest sample, under
``block`` the callback waits for room; every drop reaches the pipeline's ``dropped``
count through :meth:`Ros2Source.losses` (``source_ring``, with the synchronizer's
``sync`` and ``pending``). The source's thread hands each payload to the
:class:`~vpp_service.sources.ros2_assembler.StereoAssembler` (sync, calibration from
camera_info, cloud -> depth, counted drops). Refusals are counted by cause in
``stats()["rejected_by"]``, and ``stats()["messages"]`` follows every sample the callback
received to the one end it came to: ``used``, ``rejected``, ``ring_dropped``,
``sync_dropped``, ``pending_dropped``, ``depth_unused`` or, still held (in a ring or the
assembler; at shutdown: never matched), ``unmatched``; ``received`` is their sum.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import TYPE_CHECKING, Annotated, Any

from vpp_service.frame import StereoFrame
from vpp_service.settings import Range, Satisfies
from vpp_service.sources.base import SOURCES, Reject, SourceContext
from vpp_service.sources.network import NetworkSource, Refused
from vpp_service.sources.ros2_assembler import TF_ROLE, StereoAssembler, StereoTopics
from vpp_service.transport.ros2 import attachment, keys
from vpp_service.transport.ros2.errors import Ros2Error
from vpp_service.transport.ros2.node import RosNode

if TYPE_CHECKING:
    import zenoh


@dataclass(frozen=True)
class Ros2SourceOptions(StereoTopics):
    """Options of the ``ros2`` source: the topics of :class:`StereoTopics` plus the node.

    Attributes
    ----------
    domain_id : int
        ROS domain id (``ROS_DOMAIN_ID``).
    node_name : str
        Name of the node that holds the subscriptions.
    ring_size : int
        Samples buffered per topic between Zenoh's thread and the source's.
    poll_s : float
        Longest idle sleep between checks for a stop request or a depth wait running out.
    ros_distro : {"jazzy", "humble", "kilted", "rolling"}
        The graph's ROS 2 distribution (the type-hash segment of the subscriber tokens).
    """

    domain_id: Annotated[int, Range(0, keys.MAX_DOMAIN_ID)] = 0
    node_name: Annotated[str, Satisfies(keys.check_node_name, keys.NODE_NAME_RULE)] = "vpp_stereo_input"
    ring_size: Annotated[int, Range(1, 1000)] = 4
    poll_s: Annotated[float, Range(0.0, 1.0, lo_open=True)] = 0.02
    ros_distro: keys.Distro = "jazzy"


@SOURCES.register("ros2")
class Ros2Source(NetworkSource["zenoh.Sample"]):
    """Stereo frames from ROS 2 topics over Zenoh (see the module docstring). Needs ``context.session``."""

    Options = Ros2SourceOptions
    options: Ros2SourceOptions

    def __init__(self, options: Ros2SourceOptions, context: SourceContext) -> None:
        super().__init__(
            options, context, max_message_bytes=int(options.max_message_mb * 1024 * 1024), poll_s=options.poll_s
        )
        self._node: RosNode | None = None
        self._assembler: StereoAssembler | None = None
        self._counters["attachment_legacy"] = 0

    def open(self) -> None:
        """Declare the node, its subscribers and their tokens on the service's session."""
        session = self.session("ros2")
        o = self.options
        self._node = RosNode(session, o.domain_id, o.namespace, o.node_name, distro=o.ros_distro)
        self._node.open()
        self.open_rings(dict.fromkeys(o.roles(), o.ring_size))
        for role in o.roles():
            # /tf_static with tf2_ros' static listener QoS (transient local), the rest as the source keeps them
            qos = keys.TF_STATIC if role == TF_ROLE else self.subscription_qos()
            self._node.subscribe(o.topic(role), o.ros_type(role), functools.partial(self._on_sample, role), qos)

    def subscription_qos(self) -> keys.Qos:
        """What the source keeps per topic: best effort, volatile, ``ring_size`` deep, keep all under ``block``."""
        depth = self.options.ring_size
        if self.input_policy == "block":
            return keys.Qos(reliability=2, durability=2, history=2, depth=depth)
        return keys.Qos(reliability=2, durability=2, history=1, depth=depth)

    def waits_on(self) -> str:
        """The ROS topics subscribed to."""
        return "ROS topics " + ", ".join(self.options.topic(role) for role in self.options.roles())

    def _topic_name(self, topic: str, sample: zenoh.Sample) -> str:
        return self.options.topic(topic)

    def _admit(self, topic: str, sample: zenoh.Sample, recv_ns: int) -> zenoh.Sample:
        """The attachment check in the callback (both rmw_zenoh layouts accepted); the sample itself is queued."""
        att = sample.attachment
        try:
            _, layout = attachment.decode(att.to_bytes() if att is not None else None)
        except Ros2Error as exc:
            raise Refused(exc.reason, str(exc)) from exc
        if layout == "legacy":
            self.count("attachment_legacy")
        return sample

    def _begin(self, reject: Reject) -> None:
        self._assembler = StereoAssembler(self.options, self.context.rig, reject)

    def _handle(self, topic: str, item: zenoh.Sample, reject: Reject) -> list[StereoFrame]:
        """Assemble one sample that passed the callback's checks (the content is checked by the assembler)."""
        asm = self._assembler
        assert asm is not None  # built by _begin
        before = sum(asm.rejected_by.values())
        frames = asm.add(topic, item.payload.to_bytes())
        self.count("rejected", sum(asm.rejected_by.values()) - before)
        return frames

    def _expire(self) -> list[StereoFrame]:
        """The frames whose depth wait ran out (see :meth:`StereoAssembler.expire`)."""
        return self._assembler.expire() if self._assembler is not None else []

    def close(self) -> None:
        """Undeclare the node (the session belongs to the service)."""
        if self._node is not None:
            self._node.close()
            self._node = None

    def stats(self) -> dict[str, Any]:
        """Counters plus the assembler's (refusals by cause, sync state, cloud point counts)."""
        out = super().stats()
        early = self.refused_by()
        if self._assembler is not None:
            out.update(self._assembler.stats())
        known = out.get("rejected_by")
        by_cause: dict[str, int] = dict(known) if isinstance(known, dict) else {}
        for cause, n in early.items():  # refused by the callback's cheap checks, before a ring slot
            by_cause[cause] = by_cause.get(cause, 0) + n
        out["rejected_by"] = by_cause
        out["messages"] = self._ledger(out["received"], sum(early.values()))
        return out

    def _ledger(self, received: int, early_rejected: int) -> dict[str, int]:
        """Where the received samples ended (see the module docstring): the callback's share plus the assembler's."""
        rings, asm = self._rings, self._assembler
        held = asm.messages if asm is not None else {}
        return {
            "received": received,
            "used": held.get("used", 0),
            "rejected": early_rejected + held.get("rejected", 0),
            "ring_dropped": self.ring_dropped,
            "sync_dropped": held.get("sync_dropped", 0),
            "pending_dropped": held.get("pending_dropped", 0),
            "depth_unused": held.get("depth_unused", 0),
            "unmatched": (len(rings) if rings is not None else 0) + (asm.unmatched() if asm is not None else 0),
        }

    def losses(self) -> dict[str, int]:
        """Valid messages lost in this source, by cause: the rings (``latest``), the stereo synchronizer."""
        asm = self._assembler
        return {
            **super().losses(),
            "sync": asm.counters["sync_dropped"] if asm is not None else 0,
            "pending": asm.counters["pending_dropped"] if asm is not None else 0,
        }


__all__ = ["Ros2Source", "Ros2SourceOptions"]
