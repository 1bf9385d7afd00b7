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

The Zenoh callback only queues the sample in its topic's ring (the network
sources' one ring type, :class:`~vpp_service.queueing.ReceiveRings`, ``ring_size``
per topic): under the pipeline's ``latest`` input policy a full ring drops its
oldest sample, under ``block`` the callback waits for room; every drop reaches the
pipeline's ``dropped`` count through :meth:`Ros2Source.losses` (``source_ring``,
with the synchronizer's ``sync`` and ``pending``). The
source's thread checks each sample's size (``max_message_mb``) and attachment (both
rmw_zenoh layouts accepted), then hands the payload to the
:class:`~vpp_service.sources.ros2_assembler.StereoAssembler` (sync, calibration from
camera_info, cloud -> depth, counted drops). Refusals are counted by cause in
``stats()["rejected_by"]``, and ``stats()["messages"]`` follows every sample the callback
received to the one end it came to: ``used``, ``rejected``, ``ring_dropped``,
``sync_dropped``, ``pending_dropped``, ``depth_unused`` or, still held (in a ring or the
assembler; at shutdown: never matched), ``unmatched``; ``received`` is their sum.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Annotated

from vpp_service.frame import StereoFrame
from vpp_service.queueing import ReceiveRings
from vpp_service.settings import Range, Satisfies
from vpp_service.sources.base import SOURCES, Emit, Reject, Source, SourceContext
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
class Ros2Source(Source):
    """Stereo frames from ROS 2 topics over Zenoh (see the module docstring). Needs ``context.session``."""

    Options = Ros2SourceOptions
    needs_session = True
    network = True  # a live camera on the network: a service that resumes after a restart

    def __init__(self, options: Ros2SourceOptions, context: SourceContext) -> None:
        super().__init__(options, context)
        self.options: Ros2SourceOptions = options
        self._node: RosNode | None = None
        self._rings: ReceiveRings[zenoh.Sample] | None = None  # one ring per topic, built at open
        self._reject: Reject | None = None
        self._assembler: StereoAssembler | None = None
        self._counters.update({"received": 0, "attachment_legacy": 0})
        self._max_bytes = int(options.max_message_mb * 1024 * 1024)

    def open(self) -> None:
        """Declare the node, its subscribers and their tokens on the service's session."""
        session = self.context.session
        if session is None:
            raise ValueError("source.ros2: needs an open zenoh session (service.zenoh section)")
        o = self.options
        self._node = RosNode(session, o.domain_id, o.namespace, o.node_name, distro=o.ros_distro)
        self._node.open()
        self._rings = ReceiveRings(dict.fromkeys(o.roles(), o.ring_size), self.input_policy)
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

    def start(self, emit: Emit, reject: Reject | None = None, on_finished: Callable[[], None] | None = None) -> None:
        """Start the source's thread; ``reject`` also hears of samples the subscriber callback turns away."""
        self._reject = reject
        super().start(emit, reject, on_finished)

    def _on_sample(self, role: str, sample: zenoh.Sample) -> None:
        """Zenoh callback: the cheap checks (size, attachment), then the sample into its topic's ring.

        A sample that fails them is refused here (counted by cause) and never takes a ring slot, so a junk
        burst cannot evict genuine messages; the input policy decides what a full ring does.
        """
        assert self._rings is not None  # subscribed only after open built them
        self.count("received")
        try:
            size = len(sample.payload)
            if size > self._max_bytes:
                raise Ros2Error("too_large", f"{size} bytes > max {self._max_bytes}")
            att = sample.attachment
            _, layout = attachment.decode(att.to_bytes() if att is not None else None)
        except Ros2Error as exc:
            self.count("rejected")
            self.count(f"rejected.{exc.reason}")
            if self._reject is not None:
                self._reject(f"{self.options.topic(role)}: {exc}")
            return
        if layout == "legacy":
            self.count("attachment_legacy")
        self._rings.put(role, sample)

    def run(self, emit: Emit, reject: Reject) -> None:
        """Drain the rings, check, assemble and emit until stopped."""
        asm = StereoAssembler(self.options, self.context.rig, reject)
        self._assembler = asm
        rings = self._rings
        assert rings is not None  # run after open
        while not self.stopping():
            got = False
            for role in rings.keys:
                sample = rings.take(role)
                if sample is None:
                    continue
                got = True
                for frame in self._handle(asm, role, sample):
                    self.count("emitted")
                    emit(frame)
            for frame in asm.expire():
                self.count("emitted")
                emit(frame)
            if not got:
                rings.wait(self.options.poll_s)

    def _handle(self, asm: StereoAssembler, role: str, sample: zenoh.Sample) -> list[StereoFrame]:
        """Assemble one sample that passed the callback's checks (the content is checked by the assembler)."""
        before = sum(asm.rejected_by.values())
        frames = asm.add(role, sample.payload.to_bytes())
        self.count("rejected", sum(asm.rejected_by.values()) - before)
        return frames

    def request_stop(self) -> None:
        """Ask the thread to stop and wake it, and every callback waiting for room."""
        super().request_stop()
        if self._rings is not None:
            self._rings.close()

    def stop(self, timeout: float = 5.0) -> None:
        """Wake the thread and the callbacks, stop within ``timeout`` s and undeclare the node."""
        if self._rings is not None:
            self._rings.close()
        super().stop(timeout)

    def close(self) -> None:
        """Undeclare the node (the session belongs to the service)."""
        if self._node is not None:
            self._node.close()
            self._node = None

    def stats(self) -> dict[str, object]:  # type: ignore[override]  # nested counters, like the zenoh source
        """Counters plus the assembler's (refusals by cause, sync state, cloud point counts)."""
        counters = super().stats()
        early = {k.split(".", 1)[1]: v for k, v in counters.items() if k.startswith("rejected.")}
        out: dict[str, object] = {k: v for k, v in counters.items() if not k.startswith("rejected.")}
        out["ring_dropped"] = self._rings.dropped_total if self._rings is not None else 0
        if self._assembler is not None:
            out.update(self._assembler.stats())
        known = out.get("rejected_by")
        by_cause: dict[str, int] = dict(known) if isinstance(known, dict) else {}
        for cause, n in early.items():  # refused by the callback's cheap checks, before a ring slot
            by_cause[cause] = by_cause.get(cause, 0) + n
        out["rejected_by"] = by_cause
        out["messages"] = self._ledger(counters, sum(early.values()))
        return out

    def _ledger(self, counters: dict[str, int], early_rejected: int) -> dict[str, int]:
        """Where the received samples ended (see the module docstring): the callback's share plus the assembler's."""
        rings, asm = self._rings, self._assembler
        held = asm.messages if asm is not None else {}
        return {
            "received": counters.get("received", 0),
            "used": held.get("used", 0),
            "rejected": early_rejected + held.get("rejected", 0),
            "ring_dropped": rings.dropped_total if rings is not None else 0,
            "sync_dropped": held.get("sync_dropped", 0),
            "pending_dropped": held.get("pending_dropped", 0),
            "depth_unused": held.get("depth_unused", 0),
            "unmatched": (len(rings) if rings is not None else 0) + (asm.unmatched() if asm is not None else 0),
        }

    def losses(self) -> dict[str, int]:
        """Valid messages lost in this source, by cause: the rings (``latest``), the stereo synchronizer."""
        asm = self._assembler
        return {
            "source_ring": self._rings.dropped_total if self._rings is not None else 0,
            "sync": asm.counters["sync_dropped"] if asm is not None else 0,
            "pending": asm.counters["pending_dropped"] if asm is not None else 0,
        }


__all__ = ["Ros2Source", "Ros2SourceOptions"]
