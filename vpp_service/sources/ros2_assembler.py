"""Stereo frames from ROS 2 messages: the part the live ``ros2`` source and the ``rosbag2`` source share.

:class:`StereoAssembler` takes serialized messages by role (``left_image``,
``left_info``, ``right_image``, ``right_info``, ``depth``) and returns finished
:class:`~vpp_service.frame.StereoFrame` objects:

1. Each payload is size-checked and CDR-decoded (:mod:`vpp_service.transport.ros2.messages`;
   an ``Image`` stays a zero-copy view until its pair is complete).
2. The four stereo messages are joined like stereo_image_proc does
   (:class:`~vpp_service.transport.sync.Synchronizer`): ``exact`` = identical header
   stamps, ``approximate`` = stamps within ``sync_tolerance_ms``.
3. A complete pair takes the depth message (``PointCloud2`` or a depth ``Image``) with
   the nearest stamp within ``depth_tolerance_ms``, and decides only once no message yet
   to come can be nearer: when one has the pair's own stamp, or one stamped after the
   pair has arrived (the depth topic is in stamp order). Until then it waits, at most
   ``depth_wait_ms`` (wall clock); then it takes the nearest one there is within the
   tolerance, or goes on without depth (counted ``no_depth``: processed without VPP). So
   the choice depends on the stamps, not on whether the pair's own cloud came before or
   after its images.
4. Calibration comes from the two camera_info messages
   (:func:`~vpp_service.transport.ros2.messages.stereo_calibration`); the cloud is moved into
   the left optical frame and projected with the left ``P``
   (:func:`~vpp_service.transport.ros2.cloud.cloud_to_depth`). A frame with a cloud
   carries ``meta["lidar_like"] = True``, so the fusion step's ``auto`` depth filter
   removes its see-through points (:mod:`vpp_service.vpp.see_through`); a depth image
   is taken as registered to the left view (``False``).
5. The cloud's transform into the left optical frame: ``lidar_to_left`` when the
   configuration gives it; else identity when the cloud's ``header.frame_id`` is the left
   camera_info's, else the chain of static transforms received on ``/tf_static``
   (``tf_topic``, role ``tf_static``; :class:`~vpp_service.transport.ros2.tf.StaticTransforms`)
   from the cloud's frame to the left camera's. Without such a chain the cloud is refused
   (cause ``tf``) and the frame goes on without depth.
6. With ``rectify = true`` the images are raw (``image_raw``): each pair is rectified with
   its camera_info's ``D``, ``K``, ``R``, ``P`` as ``stereo_image_proc`` does
   (:class:`~vpp_service.rectify.StereoRectifier`, its maps built once per calibration
   and rebuilt only when the camera_info changes); the calibration comes from ``P``, a
   cloud is rotated by the left ``R`` into the rectified camera before projection with
   ``P``, a depth image is taken as registered to the raw left image and moved point by
   point. A camera_info that cannot rectify (NaN, all-zero ``P``, not a pair) refuses the
   set (cause ``calibration``).
7. With ``transport = "compressed"`` the two views come as ``sensor_msgs/CompressedImage``
   (JPEG or PNG) on ``<image topic>/compressed``, image_transport's name, and are decoded
   on arrival (:func:`~vpp_service.transport.ros2.messages.compressed_to_array`: the
   declared size bounded before decoding, a truncated or corrupt stream refused, cause
   ``corrupt``); everything else (camera_info, rectification, depth) is as with raw images.

Every refused message or pair is counted by cause in :attr:`StereoAssembler.rejected_by`
and reported through ``reject``. :attr:`StereoAssembler.messages` follows every message
offered to the end it comes to, in exactly one count: ``used`` (in a frame), ``rejected``
(refused, alone or with its stereo set), ``sync_dropped`` (passed over by the stereo
sync), ``pending_dropped`` (its complete set pushed out while waiting for depth),
``depth_unused`` (a depth message pushed out unused), or, while it is still held,
``unmatched`` (waiting for partners; at shutdown: never matched). So ``received`` is
always the sum of the others.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Annotated, Literal, cast

import numpy as np

from vpp_service.frame import StereoFrame
from vpp_service.rectify import CalibrationError, CameraInfo, StereoRectifier
from vpp_service.rectify.camera_info import DistortionModel
from vpp_service.settings import Options, Range, Satisfies, reject
from vpp_service.transport.ros2 import keys
from vpp_service.transport.ros2 import messages as rm
from vpp_service.transport.ros2.cloud import check_extrinsic, cloud_to_depth
from vpp_service.transport.ros2.errors import Ros2Error
from vpp_service.transport.ros2.tf import StaticTransforms
from vpp_service.transport.sync import Synchronizer
from vpp_service.vpp.see_through import LIDAR_LIKE

#: Roles of the subscribed topics, in the order of the stereo set.
STEREO_ROLES = ("left_image", "left_info", "right_image", "right_info")
#: Every role (``depth`` only when a depth topic is used).
ROLES = (*STEREO_ROLES, "depth")
#: The role of the static transforms (only when the cloud's transform comes from tf).
TF_ROLE = "tf_static"
#: What the depth topic carries.
DepthType = Literal["cloud", "image", "none"]
#: How the two views travel (image_transport's names): ``sensor_msgs/Image``, or ``CompressedImage`` on ``/compressed``.
Transport = Literal["raw", "compressed"]
#: The roles of the two views (their topic and type follow :attr:`StereoTopics.transport`).
IMAGE_ROLES = ("left_image", "right_image")

_ROLE_TYPES = {
    "left_image": keys.IMAGE,
    "right_image": keys.IMAGE,
    "left_info": keys.CAMERA_INFO,
    "right_info": keys.CAMERA_INFO,
}


def _extrinsic(matrix: list[list[float]]) -> None:
    """Raise ValueError unless ``matrix`` is a rigid 4 x 4 transform (:func:`check_extrinsic`)."""
    check_extrinsic(np.asarray(matrix, dtype=np.float64))


@dataclass(frozen=True)
class StereoTopics(Options):
    """Topic names (relative to the namespace unless absolute) and how frames are assembled.

    Attributes
    ----------
    namespace : str
        ROS namespace of the relative topic names.
    left_image, left_info, right_image, right_info : str
        The images (rectified, or raw with ``rectify``) and their camera_info. The image topics
        are image_transport's base topics: with ``transport = "compressed"`` the source reads
        ``<left_image>/compressed``.
    transport : {"raw", "compressed"}
        How the two views travel, as image_transport names it: ``raw`` = ``sensor_msgs/Image``
        on the image topics; ``compressed`` = ``sensor_msgs/CompressedImage`` (JPEG or PNG) on
        ``<image topic>/compressed``. The depth image (``depth_type = "image"``) is always raw.
    rectify : bool
        The images are raw (``left/image_raw``): rectify them with the camera_info's
        ``D``, ``K``, ``R``, ``P`` (module docstring, 6.).
    depth_topic : str
        Sparse depth: a ``PointCloud2`` (``depth_type = "cloud"``) or a depth ``Image``
        registered to the left camera (``"image"``: ``32FC1`` metres or ``16UC1`` mm).
    depth_type : {"cloud", "image", "none"}
        What ``depth_topic`` carries; ``none`` = no depth subscription.
    lidar_to_left : list of list of float or None
        4 x 4 transform from the cloud's frame to the left optical frame (rows). None (default):
        identity when the cloud's frame is the left camera's, else from ``tf_topic``.
    tf_topic : str
        The static transforms (``tf2_msgs/TFMessage``), subscribed when the cloud's transform
        comes from tf (``depth_type = "cloud"`` and no ``lidar_to_left``).
    sync : {"exact", "approximate"}
        Stereo matching rule (stereo_image_proc's ``approximate_sync``).
    sync_queue_size : int
        Messages kept per topic while waiting for partners (stereo_image_proc: 5).
    sync_tolerance_ms : float
        Approximate sync: largest stamp difference inside a stereo set.
    depth_tolerance_ms : float
        Largest stamp difference between a pair and its depth message.
    depth_wait_ms : float
        Longest wall time a complete pair waits for its depth message.
    max_message_mb : float
        Larger messages are refused before decoding.
    max_pixels : int
        Larger images are refused before conversion.
    max_points : int
        Larger clouds are refused before conversion.
    """

    namespace: Annotated[str, Satisfies(keys.check_namespace, "a namespace like '/stereo' (letters, digits, _)")] = (
        "/stereo"
    )
    left_image: str = "left/image_rect"
    left_info: str = "left/camera_info"
    right_image: str = "right/image_rect"
    right_info: str = "right/camera_info"
    rectify: bool = False
    transport: Transport = "raw"
    depth_topic: str = "points"
    depth_type: DepthType = "cloud"
    lidar_to_left: Annotated[list[list[float]] | None, Satisfies(_extrinsic, "a finite 4 x 4 rigid transform")] = None
    tf_topic: str = "/tf_static"
    sync: Literal["exact", "approximate"] = "exact"
    sync_queue_size: Annotated[int, Range(1, 1000)] = 5
    sync_tolerance_ms: Annotated[float, Range(0.0, 60_000.0)] = 10.0
    depth_tolerance_ms: Annotated[float, Range(0.0, 60_000.0)] = 50.0
    depth_wait_ms: Annotated[float, Range(0.0, 60_000.0)] = 100.0
    max_message_mb: Annotated[float, Range(0.0, 4096.0, lo_open=True)] = rm.Limits.max_bytes / (1024 * 1024)
    max_pixels: Annotated[int, Range(1, 1_000_000_000)] = rm.Limits.max_pixels
    max_points: Annotated[int, Range(1, 1_000_000_000)] = rm.Limits.max_points

    def cross_check(self) -> None:
        """Every role's topic is a valid ROS name under ``namespace``."""
        for role in ROLES:
            try:
                self.topic(role)
            except ValueError as exc:
                key = {"depth": "depth_topic"}.get(role, role)
                raise reject(key, getattr(self, key), f"a ROS topic name ({exc})") from None

    def topic(self, role: str) -> str:
        """The fully-qualified topic of ``role``."""
        name = {"depth": self.depth_topic, TF_ROLE: self.tf_topic}.get(role) or getattr(self, role)
        if role in IMAGE_ROLES and self.transport == "compressed":
            name = name.rstrip("/") + "/compressed"
        return keys.fully_qualified(self.namespace, name)

    def uses_tf(self) -> bool:
        """True when the cloud's transform may come from tf (a cloud, and no ``lidar_to_left``)."""
        return self.depth_type == "cloud" and self.lidar_to_left is None

    def roles(self) -> tuple[str, ...]:
        """The roles subscribed to (``depth`` unless ``depth_type`` is ``none``, ``tf_static`` when :meth:`uses_tf`)."""
        if self.depth_type == "none":
            return STEREO_ROLES
        return (*ROLES, TF_ROLE) if self.uses_tf() else ROLES

    def ros_type(self, role: str) -> str:
        """The message type of ``role``."""
        if role == TF_ROLE:
            return keys.TF_MESSAGE
        if role == "depth":
            return keys.POINT_CLOUD2 if self.depth_type == "cloud" else keys.IMAGE
        if role in IMAGE_ROLES and self.transport == "compressed":
            return keys.COMPRESSED_IMAGE
        return _ROLE_TYPES[role]

    def limits(self) -> rm.Limits:
        """The message bounds."""
        return rm.Limits(int(self.max_message_mb * 1024 * 1024), self.max_pixels, self.max_points)


@dataclass
class _Msg:
    msg: object
    stamp_ns: int
    decode_s: float
    #: The part's content, checked on arrival (image array, camera model, cloud points, depth map).
    value: object = None


@dataclass
class _Pair:
    parts: dict[str, _Msg]
    stamp_ns: int
    since: float


@dataclass
class _Depth:
    item: _Msg
    #: ``waiting`` (no frame took it yet), ``used`` (in a frame) or ``rejected`` (its content refused a set).
    state: Literal["waiting", "used", "rejected"] = "waiting"


class StereoAssembler:
    """Join serialized ROS 2 messages into stereo frames (see the module docstring).

    Parameters
    ----------
    topics : StereoTopics
        Topic names and assembly rules.
    rig : str
        Rig name given to the frames.
    reject : callable
        ``reject(reason)`` for each refused message or pair (the source's reporter).
    clock : callable
        Monotonic clock in seconds (``depth_wait_ms``); tests pass their own.

    Attributes
    ----------
    counters : dict
        ``frames``, ``no_depth``, ``sync_dropped`` (messages), ``depth_unused`` (messages),
        ``pending_dropped`` (complete sets), ``cloud_points``, ``cloud_behind``,
        ``cloud_outside``, ``cloud_nonfinite``.
    rejected_by : dict
        Refusals per cause (``too_large``, ``cdr``, ``encoding``, ...): one per refused message or set.
    messages : dict
        Where every offered message ended, in messages (see the module docstring): ``received``,
        ``used``, ``rejected``, ``sync_dropped``, ``pending_dropped``, ``depth_unused``;
        :meth:`stats` adds ``unmatched`` (those still held).
    """

    def __init__(
        self,
        topics: StereoTopics,
        rig: str,
        reject: Callable[[str], None],
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.topics = topics
        self.rig = rig
        self._reject = reject
        self._clock = clock
        self._limits = topics.limits()
        given = topics.lidar_to_left
        self._extrinsic = check_extrinsic(np.asarray(given, dtype=np.float64)) if given is not None else None
        #: The static transforms received (used when ``lidar_to_left`` is not given).
        self.tf = StaticTransforms()
        self.sync: Synchronizer[_Msg] = Synchronizer(
            STEREO_ROLES, topics.sync, topics.sync_queue_size, int(topics.sync_tolerance_ms * 1e6)
        )
        self._pending: deque[_Pair] = deque()
        self._depth: deque[_Depth] = deque()
        self._depth_waiting = 0  # entries of _depth still "waiting" (kept as a count: stats() runs on other threads)
        self._seq = 0
        self._rectifier: tuple[bytes, StereoRectifier] | None = None  # (its camera_info's bytes, the rectifier)
        self.counters: dict[str, int] = dict.fromkeys(
            (
                "frames",
                "no_depth",
                "sync_dropped",
                "depth_unused",
                "pending_dropped",
                "cloud_points",
                "cloud_behind",
                "cloud_outside",
                "cloud_nonfinite",
                "tf_messages",
            ),
            0,
        )
        self.rejected_by: dict[str, int] = {}
        self.messages: dict[str, int] = dict.fromkeys(
            ("received", "used", "rejected", "sync_dropped", "pending_dropped", "depth_unused"), 0
        )

    # ----------------------------------------------------------------- input
    def refuse(self, role: str, exc: Ros2Error) -> None:
        """Count and report a message of ``role`` refused before it was offered (e.g. recorded with another type)."""
        self.messages["received"] += 1
        self._refused(role, exc, 1)

    def _refused(self, role: str, exc: Ros2Error, messages: int) -> None:
        """Count one refusal of ``messages`` received messages (a message, or a stereo set) and report it."""
        self.rejected_by[exc.reason] = self.rejected_by.get(exc.reason, 0) + 1
        self.messages["rejected"] += messages
        self._reject(f"{self.topics.topic(role) if role in (*ROLES, TF_ROLE) else role}: {exc}")

    def add(self, role: str, payload: bytes | memoryview) -> list[StereoFrame]:
        """Offer one serialized message of ``role``; returns the frames it completes (oldest first)."""
        if role not in self.topics.roles():
            raise ValueError(f"role must be one of {list(self.topics.roles())}, got {role!r}")
        self.messages["received"] += 1
        t0 = time.perf_counter()
        ros_type = self.topics.ros_type(role)
        try:
            msg: object = rm.deserialize(payload, ros_type, rm.message_class(ros_type), self._limits)
        except Ros2Error as exc:
            self._refused(role, exc, 1)
            return []
        try:  # the content too, on arrival: a bad part never takes the slot of a valid one with its stamp
            value = self._checked(role, msg)
        except Ros2Error as exc:
            self._refused(role, exc, 1)
            return []
        if role == TF_ROLE:  # static transforms: kept for the clouds to come, no frame of their own
            assert isinstance(value, list)
            self.tf.add(value)
            self.counters["tf_messages"] += 1
            self.messages["used"] += 1
            return self._resolve()
        header = msg.header  # type: ignore[attr-defined]  # every supported message but TFMessage has one
        item = _Msg(msg, rm.stamp_ns(header), time.perf_counter() - t0, value)
        if role == "depth":
            self._depth.append(_Depth(item))
            self._depth_waiting += 1
            while len(self._depth) > 2 * self.topics.sync_queue_size:
                if self._depth.popleft().state == "waiting":
                    self._depth_waiting -= 1
                    self.counters["depth_unused"] += 1
                    self.messages["depth_unused"] += 1
            return self._resolve()
        before = self.sync.dropped + self.sync.inconsistent
        joined = self.sync.add(role, item.stamp_ns, item.stamp_ns, item)
        passed_over = self.sync.dropped + self.sync.inconsistent - before
        self.counters["sync_dropped"] += passed_over
        self.messages["sync_dropped"] += passed_over
        if joined is not None:
            self._pending.append(_Pair(joined, joined["left_info"].stamp_ns, self._clock()))
            while len(self._pending) > self.topics.sync_queue_size:
                gone = self._pending.popleft()
                self.counters["pending_dropped"] += 1
                self.messages["pending_dropped"] += len(gone.parts)
        return self._resolve()

    def _checked(self, role: str, msg: object) -> object:
        """The checked content of one part (what the frame is built from).

        Raises
        ------
        Ros2Error
            The part's content is unusable (encoding, ``step`` x ``height`` against the data, size
            limits, a camera_info without a valid ``P``, a cloud without float ``x``/``y``/``z``, a
            transform that is not rigid, a compressed view that is truncated or declares too many pixels).
        """
        if isinstance(msg, rm.CameraInfo):
            return rm.camera_model(msg)
        if isinstance(msg, rm.TFMessage):
            return rm.tf_transforms(msg)
        if isinstance(msg, rm.PointCloud2):
            return rm.cloud_to_xyz(msg, self._limits)
        if isinstance(msg, rm.CompressedImage):
            return rm.compressed_to_array(msg, self._limits)
        assert isinstance(msg, rm.Image)
        if role == "depth":
            return rm.depth_image_to_array(msg, self._limits)
        return rm.image_to_array(msg, self._limits)

    def expire(self) -> list[StereoFrame]:
        """Frames whose depth wait is over (call periodically)."""
        return self._resolve()

    def flush(self) -> list[StereoFrame]:
        """Every pending pair, with depth if one matches now (end of a bag)."""
        return self._resolve(final=True)

    # ---------------------------------------------------------------- output
    def _nearest_depth(self, stamp: int) -> _Depth | None:
        """The depth message nearest to ``stamp`` within the tolerance (the earliest received of equals)."""
        tol = int(self.topics.depth_tolerance_ms * 1e6)
        best = min(self._depth, key=lambda d: abs(d.item.stamp_ns - stamp), default=None)
        if best is None or abs(best.item.stamp_ns - stamp) > tol:
            return None
        return best

    def _depth_known(self, stamp: int) -> bool:
        """True once no depth message yet to come can be nearer to ``stamp`` than those received.

        That is when one is stamped at or after ``stamp``: the depth topic is in stamp order, so
        every later one lies further away. Deciding earlier would take a neighbour's message
        whenever the set's own one comes a moment after its images.
        """
        return any(d.item.stamp_ns >= stamp for d in self._depth)

    def _resolve(self, final: bool = False) -> list[StereoFrame]:
        out: list[StereoFrame] = []
        wait_s = self.topics.depth_wait_ms / 1e3
        while self._pending:
            pair = self._pending[0]
            depth = None
            if self.topics.depth_type != "none":
                waited = final or self._clock() - pair.since >= wait_s
                if not (waited or self._depth_known(pair.stamp_ns)):
                    break  # keep waiting, and keep the order
                depth = self._nearest_depth(pair.stamp_ns)
            self._pending.popleft()
            frame = self._frame(pair, depth)
            if frame is not None:
                out.append(frame)
        return out

    def _frame(self, pair: _Pair, depth_entry: _Depth | None) -> StereoFrame | None:
        """The frame of ``pair`` with ``depth_entry`` (counts its messages used), None when refused (counted)."""
        t0 = time.perf_counter()
        p = pair.parts
        depth = depth_entry.item if depth_entry is not None else None
        try:
            lc, rc = p["left_info"].value, p["right_info"].value  # checked on arrival
            left, right = p["left_image"].value, p["right_image"].value
            assert isinstance(lc, rm.CameraModel) and isinstance(rc, rm.CameraModel)
            assert isinstance(left, np.ndarray) and isinstance(right, np.ndarray)
            rectifier = self._rectifier_of(p["left_info"].msg, p["right_info"].msg) if self.topics.rectify else None
            calib = rm.stereo_calibration(lc, rc) if rectifier is None else rectifier.calib
            h, w = left.shape[:2]
            if left.shape != right.shape:
                raise Ros2Error("shape", f"left {left.shape} and right {right.shape} images differ")
            if (lc.width, lc.height) != (w, h):
                raise Ros2Error("shape", f"camera_info is {lc.width}x{lc.height}, images are {w}x{h}")
        except Ros2Error as exc:
            self._refused("stereo pair", exc, len(p))  # the depth message stays free for another set
            return None
        extrinsic = None
        if depth_entry is not None and isinstance(depth_entry.item.msg, rm.PointCloud2):
            try:
                extrinsic = self._cloud_to_left(depth_entry.item.msg.header.frame_id, lc.frame_id)
                if rectifier is not None:  # into the rectified left camera, which P projects
                    extrinsic = np.block([[rectifier.left.r, np.zeros((3, 1))], [np.zeros((1, 3)), 1.0]]) @ extrinsic
            except Ros2Error as exc:  # the cloud cannot be placed: refused, the frame goes on without depth
                self._refused("depth", exc, self._take(depth_entry, "rejected"))
                depth_entry = depth = None
        try:
            sensor_depth = self._depth_map(depth, lc.p, (h, w), extrinsic) if depth is not None else None
        except Ros2Error as exc:  # the depth message does not fit the set: both are refused
            assert depth_entry is not None
            self._refused("stereo pair", exc, len(p) + self._take(depth_entry, "rejected"))
            return None
        self.messages["used"] += len(p) + (self._take(depth_entry, "used") if depth_entry is not None else 0)
        if sensor_depth is None:
            self.counters["no_depth"] += 1
        decode_s = sum(m.decode_s for m in p.values()) + (depth.decode_s if depth is not None else 0.0)
        self._seq += 1
        self.counters["frames"] += 1
        frame = StereoFrame(
            left=left,
            right=right,
            calib=calib,
            sensor_depth=sensor_depth,
            name="ros2",
            rig=self.rig,
            seq=self._seq,
            stamp_ns=pair.stamp_ns,
            meta={
                "ros": {"stamp_ns": pair.stamp_ns, "frame_id": lc.frame_id},
                "timing_ms": {"decode": (decode_s + time.perf_counter() - t0) * 1e3},
                # a cloud is a LiDAR's own scan (the fusion step filters its see-through points by default)
                LIDAR_LIKE: depth is not None and isinstance(depth.msg, rm.PointCloud2),
            },
        )
        if rectifier is None:
            return frame
        cloud = depth is not None and isinstance(depth.msg, rm.PointCloud2)  # projected with P already
        rectified = rectifier(frame.with_(sensor_depth=None) if cloud else frame)
        return rectified.with_(sensor_depth=sensor_depth) if cloud else rectified

    def _rectifier_of(self, left_info: object, right_info: object) -> StereoRectifier:
        """The rectifier of a raw pair's camera_info (built once, again only when the calibration changes).

        Raises
        ------
        Ros2Error
            ``calibration``: the camera_info cannot rectify (:class:`~vpp_service.rectify.CalibrationError`).
        """
        assert isinstance(left_info, rm.CameraInfo) and isinstance(right_info, rm.CameraInfo)
        fields = [np.asarray(getattr(m, a), np.float64).tobytes() for m in (left_info, right_info) for a in "kdrp"]
        sig = b"".join(
            [*fields, repr([(m.width, m.height, m.distortion_model) for m in (left_info, right_info)]).encode()]
        )
        if self._rectifier is not None and self._rectifier[0] == sig:
            return self._rectifier[1]
        try:
            cams = [
                CameraInfo(
                    int(m.width),
                    int(m.height),
                    np.asarray(m.k),
                    np.asarray(m.d),
                    np.asarray(m.r),
                    np.asarray(m.p),
                    cast(DistortionModel, m.distortion_model),
                    name=self.topics.topic(role),
                )
                for m, role in ((left_info, "left_info"), (right_info, "right_info"))
            ]
            rectifier = StereoRectifier(cams[0], cams[1])
        except CalibrationError as exc:
            raise Ros2Error("calibration", str(exc)) from None
        self._rectifier = (sig, rectifier)
        return rectifier

    def _take(self, entry: _Depth, state: Literal["used", "rejected"]) -> int:
        """Mark a depth message ``state``; 1 when it was still waiting (counted now), else 0 (counted before)."""
        if entry.state != "waiting":
            return 0
        entry.state = state
        self._depth_waiting -= 1
        return 1

    def _cloud_to_left(self, cloud_frame: str, left_frame: str) -> np.ndarray:
        """The 4 x 4 transform of a cloud in ``cloud_frame`` into ``left_frame`` (see the module docstring, 5.).

        Raises
        ------
        Ros2Error
            ``tf``: no ``lidar_to_left`` and no chain of static transforms between the frames.
        """
        if self._extrinsic is not None:
            return self._extrinsic
        if cloud_frame.lstrip("/") == left_frame.lstrip("/"):
            return np.eye(4)
        try:
            return self.tf.lookup(left_frame, cloud_frame)
        except LookupError as exc:
            raise Ros2Error("tf", f"{exc} (or set lidar_to_left)") from None

    def _depth_map(
        self, depth: _Msg, p: np.ndarray, shape: tuple[int, int], extrinsic: np.ndarray | None
    ) -> np.ndarray:
        msg, value = depth.msg, depth.value  # checked on arrival
        assert isinstance(value, np.ndarray)
        if isinstance(msg, rm.PointCloud2):
            assert extrinsic is not None
            xyz = value
            z, counts = cloud_to_depth(xyz, extrinsic, p, shape)
            self.counters["cloud_points"] += counts.used
            self.counters["cloud_behind"] += counts.behind
            self.counters["cloud_outside"] += counts.outside
            self.counters["cloud_nonfinite"] += counts.nonfinite
            return z
        z = value
        if z.shape != shape:
            raise Ros2Error("shape", f"depth image is {z.shape[1]}x{z.shape[0]}, images are {shape[1]}x{shape[0]}")
        return z

    def unmatched(self) -> int:
        """Messages held now: waiting in the stereo sync, in complete sets waiting for depth, unused depth."""
        return sum(self.sync.pending().values()) + len(STEREO_ROLES) * len(self._pending) + self._depth_waiting

    def stats(self) -> dict[str, object]:
        """Counters, refusals by cause, where the messages ended (:attr:`messages`) and the synchronizer's state."""
        messages = {**self.messages, "unmatched": self.unmatched()}
        return {**self.counters, "rejected_by": dict(self.rejected_by), "messages": messages, "sync": self.sync.stats()}


__all__ = [
    "IMAGE_ROLES",
    "ROLES",
    "STEREO_ROLES",
    "TF_ROLE",
    "DepthType",
    "StereoAssembler",
    "StereoTopics",
    "Transport",
]
