"""rosbag2 source: play a recorded ROS 2 bag (``.db3`` or ``.mcap``) through the service.

The same topics and assembly rules as the live ``ros2`` source
(:class:`~vpp_service.sources.ros2_assembler.StereoTopics`: namespace, topic names,
cloud or depth image, ``lidar_to_left``, sync, depth tolerance); only the messages of
those topics are read. ``rate`` replays at the recorded timing times ``rate``
(``0`` = as fast as possible), ``loop`` restarts at the end, ``count`` caps the
number of frames (0 = no cap). The depth wait (``depth_wait_ms``) runs on the bag's
clock, so a fast replay pairs messages exactly as a real-time one does. A message
recorded under a topic with another type than expected is refused (``type``).

A damaged bag (cut short, garbage in a chunk or a page) is bad input, not a failure:
every readable message is played, and each damaged place is refused with its cause
(``bag.truncated``, ``bag.crc``, ``bag.corrupt_chunk``, ... of
:mod:`~vpp_service.transport.ros2.bag_damage`) and where it is (byte offset, chunk or
row, messages read before it): counted in ``rejected_by`` on the first pass (a loop
does not count the same damage again). A bag of which nothing at all can be read
ends the source with an error naming the file and the damage.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Annotated

from vpp_service.frame import StereoFrame
from vpp_service.settings import NonEmpty, Range
from vpp_service.sources.base import SOURCES, Emit, Reject, Source, SourceContext
from vpp_service.sources.ros2_assembler import StereoAssembler, StereoTopics
from vpp_service.transport.ros2.bag import check_bag_path, read_bag
from vpp_service.transport.ros2.bag_damage import BagDamage, ignore_damage
from vpp_service.transport.ros2.errors import Ros2Error


@dataclass(frozen=True)
class Rosbag2SourceOptions(StereoTopics):
    """Options of the ``rosbag2`` source: :class:`StereoTopics` plus the bag and its replay.

    Attributes
    ----------
    path : str
        Bag folder (with ``metadata.yaml``) or ``.db3`` / ``.mcap`` file (required).
    rate : float
        Multiplier of the recorded timing; 0 = as fast as possible.
    loop : bool
        Restart at the end of the bag.
    count : int
        Frames to emit in total; 0 = no cap.
    """

    path: Annotated[str, NonEmpty()] = ""
    rate: Annotated[float, Range(0.0, 1000.0)] = 1.0
    loop: bool = False
    count: Annotated[int, Range(0)] = 0


@SOURCES.register("rosbag2")
class Rosbag2Source(Source):
    """Stereo frames from a rosbag2 bag (see the module docstring)."""

    finite = True  # a replay: back-pressured, loses nothing by default

    Options = Rosbag2SourceOptions

    @classmethod
    def check_options(cls, options: Rosbag2SourceOptions, section: str) -> None:
        """The bag must exist (checked when the config is validated)."""
        from vpp_service.settings import SettingsError

        try:
            check_bag_path(options.path)
        except (FileNotFoundError, ValueError) as exc:
            raise SettingsError(f"{section}.path: {exc}") from None

    def __init__(self, options: Rosbag2SourceOptions, context: SourceContext) -> None:
        super().__init__(options, context)
        self.options: Rosbag2SourceOptions = options
        self._assembler: StereoAssembler | None = None
        self._bag_s = 0.0
        self._counters.update({"read": 0, "passes": 0})

    def run(self, emit: Emit, reject: Reject) -> None:
        """Read, pace, assemble and emit until the end (or ``count``), looping if asked."""
        o = self.options
        asm = StereoAssembler(o, self.context.rig, reject, clock=lambda: self._bag_s)
        self._assembler = asm
        roles = {o.topic(r): r for r in o.roles()}
        while not self.stopping():
            got = False
            start_wall, start_bag = time.monotonic(), None
            on_damage = self._damaged if self._counters["passes"] == 0 else ignore_damage
            for m in read_bag(o.path, roles, on_damage):
                got = True
                self._counters["read"] += 1
                self._bag_s = m.log_time_ns / 1e9
                start_bag = m.log_time_ns if start_bag is None else start_bag
                if o.rate > 0:
                    delay = start_wall + (m.log_time_ns - start_bag) / 1e9 / o.rate - time.monotonic()
                    if delay > 0 and self.wait(delay):
                        return
                if self.stopping():
                    return
                role = roles[m.topic]
                if m.ros_type != o.ros_type(role):
                    self._counters["rejected"] += 1
                    asm.refuse(role, Ros2Error("type", f"recorded as {m.ros_type}, expected {o.ros_type(role)}"))
                    continue
                before = sum(asm.rejected_by.values())
                frames = asm.add(role, m.data)
                self._counters["rejected"] += sum(asm.rejected_by.values()) - before
                if self._emit_all(frames, emit):
                    return
            if self._emit_all(asm.flush(), emit):
                return
            self._counters["passes"] += 1
            if not (o.loop and got):
                return

    def _damaged(self, damage: BagDamage) -> None:
        """Count and report a damaged place of the bag (refused like a bad message)."""
        if self._assembler is not None:
            self._counters["rejected"] += 1
            self._assembler.refuse("bag", Ros2Error(damage.cause, damage.where))

    def _emit_all(self, frames: list[StereoFrame], emit: Emit) -> bool:
        """Emit ``frames``; True when ``count`` is reached."""
        cap = self.options.count
        for frame in frames:
            if cap and self._counters["emitted"] >= cap:
                return True
            self._counters["emitted"] += 1
            emit(frame)
        return bool(cap) and self._counters["emitted"] >= cap

    def stats(self) -> dict[str, object]:  # type: ignore[override]  # nested counters, like the ros2 source
        """Counters plus the assembler's."""
        out: dict[str, object] = dict(self._counters)
        if self._assembler is not None:
            out.update(self._assembler.stats())
        return out


__all__ = ["Rosbag2Source", "Rosbag2SourceOptions"]
