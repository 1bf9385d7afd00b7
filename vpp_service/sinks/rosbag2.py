"""rosbag2 sink: record the ROS 2 outputs into a new bag (MCAP by default) for Foxglove, rviz or ``ros2 bag``.

The messages are exactly what the ``ros2`` sink publishes (:class:`~vpp_service.sinks.ros2.Ros2Encoder`:
``disparity``, ``depth``, ``points2``, ``left_vpp``, ``right_vpp`` under ``namespace``), each
logged at its header stamp. ``path`` is the bag folder to create: it must not exist (a
recording never overwrites). Writing happens on the sink's own thread
(:class:`~vpp_service.queueing.QueueWorker`, policy ``block``: a recording is lossless, the
pipeline's output queue absorbs the wait); the thread creates the bag and, on ``close``, finishes it
(``metadata.yaml``).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

from vpp_service.frame import FusionResult
from vpp_service.queueing import QueueWorker
from vpp_service.sinks.base import SINKS, Sink, SinkContext
from vpp_service.sinks.ros2 import OUTPUTS, Ros2Encoder, Ros2OutputOptions
from vpp_service.transport.ros2.bag import BagWriter, Storage
from vpp_service.transport.ros2.messages import stamp_ns

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Rosbag2SinkOptions(Ros2OutputOptions):
    """Options of the ``rosbag2`` sink: :class:`~vpp_service.sinks.ros2.Ros2OutputOptions` plus the bag.

    Attributes
    ----------
    path : str
        Bag folder to create (required; must not exist).
    storage : {"mcap", "sqlite3"}
        Storage format.
    """

    path: str = ""
    storage: Storage = "mcap"

    def __post_init__(self) -> None:
        super().__post_init__()
        if not self.path:
            raise ValueError("path: required (the bag folder to create)")


@SINKS.register("rosbag2")
class Rosbag2Sink(Sink):
    """Record results as a rosbag2 bag (see the module docstring)."""

    Options = Rosbag2SinkOptions

    @classmethod
    def check_options(cls, options: Rosbag2SinkOptions, section: str) -> None:
        """The bag folder must not exist yet (checked when the config is validated)."""
        from vpp_service.settings import SettingsError

        if Path(options.path).exists():
            raise SettingsError(f"{section}.path: {options.path} exists already (a recording never overwrites)")

    @classmethod
    def needs_depth(cls, options: Rosbag2SinkOptions) -> bool:
        """True when ``depth`` or ``points2`` is recorded."""
        return "depth" in options.outputs or "points2" in options.outputs

    def __init__(self, options: Rosbag2SinkOptions, context: SinkContext) -> None:
        super().__init__(options, context)
        self.options: Rosbag2SinkOptions = options
        self._encoder = Ros2Encoder(options)
        self._bag: BagWriter | None = None
        self._worker: QueueWorker[FusionResult] = QueueWorker(
            self._record,
            size=options.queue_size,
            policy="block",
            name="sink-rosbag2",
            on_start=self._open_bag,
            on_exit=self._close_bag,
            on_error=self._failed,
        )
        self._counters.update({"messages": 0, "missing": 0})

    def open(self) -> None:
        """Start the writing thread (which creates the bag: sqlite3 handles stay on one thread)."""
        Path(self.options.path).parent.mkdir(parents=True, exist_ok=True)
        self._worker.start()

    def _open_bag(self) -> None:
        self._bag = BagWriter(self.options.path, self.options.storage)

    def _close_bag(self) -> None:
        if self._bag is not None:
            self._bag.close()
            self._bag = None

    def write(self, result: FusionResult) -> None:
        """Queue ``result`` for recording (waits for room: a recording is lossless)."""
        if not self._worker.put(result):
            self._counters["dropped"] += 1

    def _record(self, result: FusionResult) -> None:
        if self._bag is None:
            raise RuntimeError(f"the bag {self.options.path} could not be created")
        t = stamp_ns(self._encoder.header(result))
        for name in self.options.outputs:
            payload = self._encoder.encode(result, name)
            if payload is None:
                self._counters["missing"] += 1
                continue
            self._bag.write(self.options.topic(name), OUTPUTS[name][1], t, payload)
            self._counters["messages"] += 1
        self._counters["written"] += 1

    def _failed(self, result: FusionResult, exc: Exception) -> None:
        self._counters["errors"] += 1
        log.warning("rosbag2 sink: %s", exc)

    def close(self, timeout: float = 5.0) -> None:
        """Record what is queued within ``timeout`` seconds; the thread then finishes the bag."""
        if not self._worker.close(timeout):
            self._counters["dropped"] += self._worker.discarded


__all__ = ["Rosbag2Sink", "Rosbag2SinkOptions"]
