"""ROS 2 source: subscribe to a stereo rig's topics as an ``rmw_zenoh`` node does.

Under ``namespace`` (default ``/stereo``) and ``domain_id`` (default 0) it subscribes
to ``left/image_rect``, ``left/camera_info``, ``right/image_rect``, ``right/camera_info``
and the sparse depth on ``points`` (a ``PointCloud2``, or with ``depth_type = "image"``
a depth ``Image`` registered to the left camera); every name is an option, and an
absolute name (``/velodyne_points``) ignores the namespace. It declares a node token
and one subscriber token per topic, so lazy publishers start sending.

The Zenoh callback only appends the sample to a bounded ring per
topic (``ring_size``; the oldest is dropped and counted in ``ring_dropped``). The
source's thread checks each sample's size (``max_message_mb``) and attachment (both
rmw_zenoh layouts accepted), then hands the payload to the
:class:`~vpp_service.sources.ros2_assembler.StereoAssembler` (sync, calibration from
camera_info, cloud -> depth, counted drops). Refusals are counted by cause in
``stats()["rejected_by"]``.
"""

from __future__ import annotations

import functools
import threading
from collections import deque
from dataclasses import dataclass
from typing import TYPE_CHECKING

from vpp_service.frame import StereoFrame
from vpp_service.sources.base import SOURCES, Emit, Reject, Source, SourceContext
from vpp_service.sources.ros2_assembler import StereoAssembler, StereoTopics
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
    """

    domain_id: int = 0
    node_name: str = "vpp_stereo_input"
    ring_size: int = 4
    poll_s: float = 0.02

    def __post_init__(self) -> None:
        super().__post_init__()
        keys.check_domain(self.domain_id)
        keys.check_node_name(self.node_name)
        if not 1 <= self.ring_size <= 1000:
            raise ValueError(f"ring_size must be in [1, 1000], got {self.ring_size}")
        if not 0 < self.poll_s <= 1:
            raise ValueError(f"poll_s must be in (0, 1], got {self.poll_s}")


@SOURCES.register("ros2")
class Ros2Source(Source):
    """Stereo frames from ROS 2 topics over Zenoh (see the module docstring). Needs ``context.session``."""

    Options = Ros2SourceOptions
    needs_session = True

    def __init__(self, options: Ros2SourceOptions, context: SourceContext) -> None:
        super().__init__(options, context)
        self.options: Ros2SourceOptions = options
        self._node: RosNode | None = None
        self._rings: dict[str, deque[zenoh.Sample]] = {}
        self._ring_lock = threading.Lock()
        self._arrived = threading.Event()
        self._assembler: StereoAssembler | None = None
        self._counters.update({"received": 0, "ring_dropped": 0, "attachment_legacy": 0})
        self._max_bytes = int(options.max_message_mb * 1024 * 1024)

    def open(self) -> None:
        """Declare the node, its subscribers and their tokens on the service's session."""
        session = self.context.session
        if session is None:
            raise ValueError("source.ros2: needs an open zenoh session (service.zenoh section)")
        o = self.options
        self._node = RosNode(session, o.domain_id, o.namespace, o.node_name)
        self._node.open()
        for role in o.roles():
            self._rings[role] = deque(maxlen=o.ring_size)
            self._node.subscribe(o.topic(role), o.ros_type(role), functools.partial(self._on_sample, role))

    def waits_on(self) -> str:
        """The ROS topics subscribed to."""
        return "ROS topics " + ", ".join(self.options.topic(role) for role in self.options.roles())

    def _on_sample(self, role: str, sample: zenoh.Sample) -> None:
        """Zenoh callback: buffer the sample and wake the source's thread."""
        ring = self._rings[role]
        with self._ring_lock:
            if len(ring) == ring.maxlen:
                self._counters["ring_dropped"] += 1
            ring.append(sample)
        self._arrived.set()

    def _next(self, role: str) -> zenoh.Sample | None:
        with self._ring_lock:
            ring = self._rings[role]
            return ring.popleft() if ring else None

    def run(self, emit: Emit, reject: Reject) -> None:
        """Drain the rings, check, assemble and emit until stopped."""
        asm = StereoAssembler(self.options, self.context.rig, reject)
        self._assembler = asm
        while not self.stopping():
            self._arrived.clear()
            got = False
            for role in list(self._rings):
                sample = self._next(role)
                if sample is None:
                    continue
                got = True
                self._counters["received"] += 1
                for frame in self._handle(asm, role, sample):
                    self._counters["emitted"] += 1
                    emit(frame)
            for frame in asm.expire():
                self._counters["emitted"] += 1
                emit(frame)
            if not got:
                self._arrived.wait(self.options.poll_s)

    def _handle(self, asm: StereoAssembler, role: str, sample: zenoh.Sample) -> list[StereoFrame]:
        try:
            size = len(sample.payload)
            if size > self._max_bytes:
                raise Ros2Error("too_large", f"{size} bytes > max {self._max_bytes}")
            att = sample.attachment
            _, layout = attachment.decode(att.to_bytes() if att is not None else None)
        except Ros2Error as exc:
            self._counters["rejected"] += 1
            asm.refuse(role, exc)
            return []
        if layout == "legacy":
            self._counters["attachment_legacy"] += 1
        before = sum(asm.rejected_by.values())
        frames = asm.add(role, sample.payload.to_bytes())
        self._counters["rejected"] += sum(asm.rejected_by.values()) - before
        return frames

    def request_stop(self) -> None:
        """Ask the thread to stop and wake it."""
        super().request_stop()
        self._arrived.set()

    def stop(self, timeout: float = 5.0) -> None:
        """Wake the thread, stop it within ``timeout`` s and undeclare the node."""
        self._arrived.set()
        super().stop(timeout)

    def close(self) -> None:
        """Undeclare the node (the session belongs to the service)."""
        if self._node is not None:
            self._node.close()
            self._node = None

    def stats(self) -> dict[str, object]:  # type: ignore[override]  # nested counters, like the zenoh source
        """Counters plus the assembler's (refusals by cause, sync state, cloud point counts)."""
        out: dict[str, object] = dict(self._counters)
        if self._assembler is not None:
            out.update(self._assembler.stats())
        return out


__all__ = ["Ros2Source", "Ros2SourceOptions"]
