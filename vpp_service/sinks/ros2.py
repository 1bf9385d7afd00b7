"""ROS 2 sink: publish results as an ``rmw_zenoh`` node does, for rviz, Foxglove and ``ros2 topic echo``.

Under ``namespace`` (default ``/stereo``) and ``domain_id`` (default 0), outputs
(``outputs``; topic names remappable with ``topics``):

``disparity`` -> ``disparity``
    ``stereo_msgs/DisparityImage`` as stereo_image_proc fills it: ``32FC1``, header =
    the left camera_info header (stamp and frame_id), ``f``, ``t``, ``min_disparity``,
    ``max_disparity``, ``delta_d``, ``valid_window`` (the bounding box of valid pixels);
    values are ``x_l - x_r - (cx_l - cx_r)`` and invalid pixels hold ``min_disparity - 1``
    (or NaN with ``invalid = "nan"``), see :mod:`vpp_service.transport.ros2.messages`.
``depth`` -> ``depth``
    ``sensor_msgs/Image`` ``32FC1``, metres, NaN = invalid.
``confidence`` -> ``confidence``
    ``sensor_msgs/Image`` ``32FC1``, the per-pixel confidence of the disparity in 0..1 (0 = no
    answer); computed only when an output asks for it (for matchers other than census-sgm a
    second matching pass).
``points2`` -> ``points2``
    ``sensor_msgs/PointCloud2``, x y z rgb in the left optical frame. ``points2_layout =
    "organized"`` (default) as stereo_image_proc's point_cloud_node publishes it: height =
    image rows, width = columns, one point per pixel, invalid pixels NaN (their colour kept),
    ``is_dense`` false, so nodes that index the cloud by pixel work on it; ``"valid_only"``:
    the valid pixels only, unorganized (height 1), a smaller message.
``left_vpp`` / ``right_vpp`` -> ``left/image_vpp`` / ``right/image_vpp``
    The painted pair, ``rgb8``.

Each publisher has a liveliness token and every sample the attachment (``current``
33-byte layout, or ``legacy`` for Jazzy rmw_zenoh 0.2.0-0.2.3). ``ros_distro`` picks the
type-hash segment of keys and tokens (``humble``: ``TypeHashNotSupported``; ``jazzy``,
``kilted``, ``rolling``: RIHS01), so subscribers of that distro receive the samples. The
products (disparity, depth, points2) declare reliable + keep all and publish with congestion
control BLOCK; the painted pair reliable + keep last 10, DROP (it gives way under load), as
rmw_zenoh maps QoS. With ``lazy = true`` an output with no ROS subscriber token for its topic,
type and hash on the graph is not serialized (counted in ``lazy_skipped``).
Frames from a non-ROS source get the header stamp ``frame.stamp_ns`` and ``frame_id``.

``write`` encodes and publishes one result, synchronously; the pipeline runs it on this
sink's own thread behind a queue of ``queue_size`` results (:meth:`Ros2Sink.queue_spec`).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Annotated, Literal

import numpy as np

from vpp_service.frame import FusionResult
from vpp_service.settings import Each, NonEmpty, OneOf, Options, Range, Satisfies, Unique, reject
from vpp_service.sinks.base import SINKS, QueueSpec, Sink, SinkContext
from vpp_service.timing import StageTimer
from vpp_service.transport.backproject import depth_to_points
from vpp_service.transport.ros2 import keys
from vpp_service.transport.ros2 import messages as rm
from vpp_service.transport.ros2.attachment import Layout
from vpp_service.transport.ros2.node import RosNode, RosPublisher

log = logging.getLogger(__name__)

#: Seconds between two looks at the graph for subscribers keyed for another distribution.
HASH_CHECK_S = 2.0

#: Output name -> (default topic relative to the namespace, message type).
OUTPUTS: dict[str, tuple[str, str]] = {
    "disparity": ("disparity", keys.DISPARITY_IMAGE),
    "depth": ("depth", keys.IMAGE),
    "confidence": ("confidence", keys.IMAGE),
    "points2": ("points2", keys.POINT_CLOUD2),
    "left_vpp": ("left/image_vpp", keys.IMAGE),
    "right_vpp": ("right/image_vpp", keys.IMAGE),
}


@dataclass(frozen=True)
class Ros2OutputOptions(Options):
    """What the ROS 2 outputs hold: shared by the ``ros2`` sink and the ``rosbag2`` recorder.

    Attributes
    ----------
    namespace : str
        ROS namespace of the output topics.
    outputs : list of str
        Which of ``disparity``, ``depth``, ``confidence``, ``points2``, ``left_vpp``, ``right_vpp`` to write.
    topics : dict
        Topic remapping per output name, e.g. ``{disparity = "/robot/disparity"}``.
    frame_id : str
        Header frame of results whose frame did not come from ROS.
    min_disparity : float
        The matcher's smallest disparity (project units; written corrected).
    max_disparity : float
        The matcher's largest disparity; 0 = each frame's largest valid value.
    delta_d : float
        Smallest disparity step (1/16 for OpenCV's matchers).
    invalid : {"below_min", "nan"}
        Value of invalid disparity pixels.
    points2_layout : {"organized", "valid_only"}
        ``points2`` as stereo_image_proc publishes it (one point per pixel, invalid ones NaN), or
        the valid points only (height 1).
    queue_size : int
        Results buffered between the pipeline and the writing thread.
    """

    namespace: Annotated[str, Satisfies(keys.check_namespace, "a namespace like '/stereo' (letters, digits, _)")] = (
        "/stereo"
    )
    outputs: Annotated[list[str], NonEmpty(), Unique(), Each(OneOf(*OUTPUTS))] = field(
        default_factory=lambda: ["disparity"]
    )
    topics: dict[str, str] = field(default_factory=dict)
    frame_id: str = "left_camera_optical_frame"
    min_disparity: Annotated[float, Range()] = 0.0
    max_disparity: Annotated[float, Range(0.0)] = 0.0
    delta_d: Annotated[float, Range(0.0, 1.0, lo_open=True)] = 1.0 / 16.0
    invalid: rm.Invalid = "below_min"
    points2_layout: Literal["organized", "valid_only"] = "organized"
    queue_size: Annotated[int, Range(1, 1000)] = 4

    def cross_check(self) -> None:
        """``topics`` keys are outputs; every output's topic is a valid ROS name."""
        for name in self.topics:
            if name not in OUTPUTS:
                raise reject("topics", name, "keys among " + ", ".join(repr(o) for o in OUTPUTS))
        for name in self.outputs:
            try:
                self.topic(name)
            except ValueError as exc:
                raise reject(
                    f"topics.{name}", self.topics.get(name, OUTPUTS[name][0]), f"a ROS topic name ({exc})"
                ) from None

    def topic(self, output: str) -> str:
        """The fully-qualified topic of ``output``."""
        return keys.fully_qualified(self.namespace, self.topics.get(output, OUTPUTS[output][0]))


@dataclass(frozen=True)
class Ros2SinkOptions(Ros2OutputOptions):
    """Options of the ``ros2`` sink: :class:`Ros2OutputOptions` plus the node.

    Attributes
    ----------
    domain_id : int
        ROS domain id.
    node_name : str
        Name of the publishing node.
    attachment : {"current", "legacy"}
        Attachment layout (``legacy`` only for Jazzy rmw_zenoh 0.2.0-0.2.3 graphs).
    lazy : bool
        Skip an output while no ROS subscriber token for its topic, type and hash is on the graph.
    ros_distro : {"jazzy", "humble", "kilted", "rolling"}
        The subscribers' ROS 2 distribution: the type-hash segment of keys and tokens.
    """

    domain_id: Annotated[int, Range(0, keys.MAX_DOMAIN_ID)] = 0
    node_name: Annotated[str, Satisfies(keys.check_node_name, keys.NODE_NAME_RULE)] = "vpp_stereo"
    attachment: Layout = "current"
    lazy: bool = False
    ros_distro: keys.Distro = "jazzy"


class Ros2Encoder:
    """CDR payloads of the outputs of one result (see the module docstring for what each holds).

    Parameters
    ----------
    options : Ros2OutputOptions
        Outputs, frame id and the ``DisparityImage`` metadata.
    """

    def __init__(self, options: Ros2OutputOptions) -> None:
        self.options = options
        self.range = rm.DisparityRange(options.min_disparity, options.max_disparity, options.delta_d, options.invalid)

    def header(self, result: FusionResult) -> rm.Header:
        """The left camera_info header the frame came with, else ``frame.stamp_ns`` and ``frame_id``."""
        ros = result.frame.meta.get("ros")
        if isinstance(ros, dict) and isinstance(ros.get("stamp_ns"), int) and isinstance(ros.get("frame_id"), str):
            return rm.make_header(ros["stamp_ns"], ros["frame_id"])
        return rm.make_header(max(0, int(result.frame.stamp_ns)), self.options.frame_id)

    def encode(self, result: FusionResult, name: str) -> bytes | bytearray | None:
        """The CDR payload of output ``name`` for ``result``; None when the result lacks it."""
        header = self.header(result)
        calib = result.frame.calib
        msg: object
        if name == "disparity":
            if calib is None:
                return None
            msg = rm.disparity_message(result.disparity, calib, header, self.range)
        elif name == "depth":
            if result.depth is None:
                return None
            msg = rm.array_to_image(np.asarray(result.depth, np.float32), header, "32FC1")
        elif name == "confidence":
            if result.confidence is None:
                return None
            msg = rm.array_to_image(np.asarray(result.confidence, np.float32), header, "32FC1")
        elif name == "points2":
            if result.depth is None or calib is None:
                return None
            organized = self.options.points2_layout == "organized"
            xyz, rgb = depth_to_points(result.depth, result.frame.left, calib, organized=organized)
            msg = rm.xyz_cloud_message(xyz, header, rgb, result.depth.shape if organized else None)
        else:
            img = result.left_vpp if name == "left_vpp" else result.right_vpp
            if img is None:
                return None
            rgb = img if img.ndim == 3 else np.repeat(img[:, :, None], 3, axis=2)
            msg = rm.array_to_image(np.ascontiguousarray(rgb, np.uint8), header, "rgb8")
        return rm.serialize(msg, OUTPUTS[name][1])


@SINKS.register("ros2")
class Ros2Sink(Sink):
    """Publish results on ROS 2 topics over Zenoh (see the module docstring). Needs ``context.session``."""

    Options = Ros2SinkOptions
    needs_session = True

    @classmethod
    def needs_depth(cls, options: Ros2SinkOptions) -> bool:
        """True when ``depth`` or ``points2`` is published."""
        return "depth" in options.outputs or "points2" in options.outputs

    @classmethod
    def needs_confidence(cls, options: Ros2SinkOptions) -> bool:
        """True when ``confidence`` is published."""
        return "confidence" in options.outputs

    def __init__(self, options: Ros2SinkOptions, context: SinkContext) -> None:
        super().__init__(options, context)
        self.options: Ros2SinkOptions = options
        self._node: RosNode | None = None
        self._pubs: dict[str, RosPublisher] = {}
        self._timer = StageTimer()  # per-result encode + publish durations (ms), the median in stats()
        self._counters.update({"lazy_skipped": 0, "missing": 0})
        self._encoder = Ros2Encoder(options)
        self._next_hash_check = 0.0
        self._hash_said: set[tuple[str, str]] = set()

    def queue_spec(self) -> QueueSpec:
        """``queue_size`` results wait for this sink (a full queue drops the oldest unless the pipeline blocks)."""
        return QueueSpec(size=self.options.queue_size)

    def open(self) -> None:
        """Declare the node and one publisher (and token) per output."""
        session = self.context.session
        if session is None:
            raise ValueError("sinks.ros2: needs an open zenoh session (service.zenoh section)")
        o = self.options
        self._node = RosNode(session, o.domain_id, o.namespace, o.node_name, distro=o.ros_distro)
        self._node.open()
        for name in o.outputs:
            visual = name in ("left_vpp", "right_vpp")
            qos = keys.DEFAULT_PUBLISHER if visual else keys.RELIABLE_KEEP_ALL
            self._pubs[name] = self._node.publisher(o.topic(name), OUTPUTS[name][1], qos, low_priority=visual)

    def write(self, result: FusionResult) -> None:
        """Encode and publish every output of one result.

        Raises
        ------
        RuntimeError
            If the sink is not open.
        """
        if self._node is None:
            raise RuntimeError("ros2 sink: not open")
        t0 = time.perf_counter()
        self._say_other_hashes()
        for name, pub in self._pubs.items():
            if self.options.lazy and not pub.live:
                self.count("lazy_skipped")
                continue
            payload = self._encoder.encode(result, name)
            if payload is None:
                self.count("missing")
                continue
            pub.put(payload, self.options.attachment)
        self._timer.add("publish", (time.perf_counter() - t0) * 1e3)
        self.count("written")

    def _say_other_hashes(self) -> None:
        """Warn once per topic and hash when a subscriber of another distribution waits on an output.

        Looked at every :data:`HASH_CHECK_S` seconds at most: the graph is a shared dictionary.
        """
        now = time.monotonic()
        if now < self._next_hash_check:
            return
        self._next_hash_check = now + HASH_CHECK_S
        for pub in self._pubs.values():
            for h in pub.other_hashes():
                if (pub.topic, h) not in self._hash_said:
                    self._hash_said.add((pub.topic, h))
                    log.warning(
                        "ros2 sink: a subscriber of %s is keyed with type hash %s, which this sink "
                        "(ros_distro = %r) does not publish: it receives nothing. Set ros_distro to its "
                        "distribution (humble: TypeHashNotSupported), or add a second ros2 sink for it",
                        pub.topic,
                        h,
                        self.options.ros_distro,
                    )

    def close(self, timeout: float = 5.0) -> None:
        """Undeclare the node."""
        if self._node is not None:
            self._node.close()
            self._node = None
        self._pubs.clear()

    def stats(self) -> dict[str, object]:  # type: ignore[override]  # nested timing, like the zenoh sink
        """Counters plus ``timing_ms.publish``: median encode + put time per result (recent window)."""
        out: dict[str, object] = dict(super().stats())
        out["timing_ms"] = self._timer.medians()
        return out


__all__ = ["OUTPUTS", "Ros2Encoder", "Ros2OutputOptions", "Ros2Sink", "Ros2SinkOptions"]
