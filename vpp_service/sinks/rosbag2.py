"""rosbag2 sink: record the ROS 2 outputs into a new bag (MCAP by default) for Foxglove, rviz or ``ros2 bag``.

The messages are exactly what the ``ros2`` sink publishes (:class:`~vpp_service.sinks.ros2.Ros2Encoder`:
``disparity``, ``depth``, ``points2``, ``left_vpp``, ``right_vpp`` under ``namespace``), each
logged at its header stamp. ``path`` is the bag folder to create: it must not exist (a
recording never overwrites). The pipeline runs this sink on its own thread behind a queue
that never drops (:meth:`Rosbag2Sink.queue_spec`: ``block``, a recording is lossless and the
pipeline waits instead); that thread creates the bag (:meth:`~Rosbag2Sink.start`), writes it and
finishes it (:meth:`~Rosbag2Sink.finish`: ``metadata.yaml``), so sqlite3 handles stay on one thread.

Like ``ros2 bag record``, each topic carries the QoS its publisher offers (the ``ros2`` sink's
publishers: reliable, volatile, keep last 10, :data:`~vpp_service.transport.ros2.keys.DEFAULT_PUBLISHER`)
and the bag the distribution it is for (``ros_distro``, in that distribution's metadata form),
so ``ros2 bag play`` republishes with that QoS.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

from vpp_service.frame import FusionResult
from vpp_service.settings import NonEmpty
from vpp_service.sinks.base import SINKS, QueueSpec, Sink, SinkContext
from vpp_service.sinks.ros2 import OUTPUTS, Ros2Encoder, Ros2OutputOptions
from vpp_service.transport.ros2.bag import BagWriter, RosDistro, Storage
from vpp_service.transport.ros2.keys import DEFAULT_PUBLISHER
from vpp_service.transport.ros2.messages import stamp_ns


@dataclass(frozen=True)
class Rosbag2SinkOptions(Ros2OutputOptions):
    """Options of the ``rosbag2`` sink: :class:`~vpp_service.sinks.ros2.Ros2OutputOptions` plus the bag.

    Attributes
    ----------
    path : str
        Bag folder to create (required; must not exist).
    storage : {"mcap", "sqlite3"}
        Storage format.
    ros_distro : {"jazzy", "humble"}
        The ROS distribution that plays the bag: ``metadata.yaml`` in its form (version 9, or
        8 with Humble's QoS encoding) and its name in ``ros_distro``.
    """

    path: Annotated[str, NonEmpty()] = ""
    storage: Storage = "mcap"
    ros_distro: RosDistro = "jazzy"


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

    @classmethod
    def needs_confidence(cls, options: Rosbag2SinkOptions) -> bool:
        """True when ``confidence`` is recorded."""
        return "confidence" in options.outputs

    def __init__(self, options: Rosbag2SinkOptions, context: SinkContext) -> None:
        super().__init__(options, context)
        self.options: Rosbag2SinkOptions = options
        self._encoder = Ros2Encoder(options)
        self._bag: BagWriter | None = None
        self._counters.update({"messages": 0, "missing": 0})

    def queue_spec(self) -> QueueSpec:
        """``queue_size`` results, never dropped: a recording is lossless (the pipeline waits for room)."""
        return QueueSpec(size=self.options.queue_size, policy="block")

    def open(self) -> None:
        """Create the bag's parent folder (the bag itself is created on the writing thread)."""
        Path(self.options.path).parent.mkdir(parents=True, exist_ok=True)

    def start(self) -> None:
        """Create the bag, on the thread that writes it (sqlite3 handles stay on one thread)."""
        self._bag = BagWriter(self.options.path, self.options.storage, self.options.ros_distro)

    def finish(self) -> None:
        """Finish the bag (``metadata.yaml``), on the thread that wrote it."""
        if self._bag is not None:
            self._bag.close()
            self._bag = None

    def write(self, result: FusionResult) -> None:
        """Record every output of one result (creates the bag first when :meth:`start` has not run)."""
        if self._bag is None:
            self.start()
        assert self._bag is not None
        t = stamp_ns(self._encoder.header(result))
        for name in self.options.outputs:
            payload = self._encoder.encode(result, name)
            if payload is None:
                self.count("missing")
                continue
            # the QoS the ros2 sink's publisher of this output offers
            self._bag.write(self.options.topic(name), OUTPUTS[name][1], t, payload, DEFAULT_PUBLISHER)
            self.count("messages")
        self.count("written")

    def close(self, timeout: float = 5.0) -> None:
        """Finish the bag if :meth:`finish` has not (a sink written without the pipeline)."""
        self.finish()


__all__ = ["Rosbag2Sink", "Rosbag2SinkOptions"]
