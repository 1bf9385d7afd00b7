"""A ROS 2 "robot" written from the rmw_zenoh contract alone (rosbags + zenoh, none of vpp_service's ROS code).

It publishes a rectified stereo pair, both camera_info and a PointCloud2 (or, with its own
``topics``, raw images, ``CompressedImage`` views as image_transport's ``compressed``
plugin writes them, a raw camera's camera_info) the way an rmw_zenoh node does (keys
``<domain>/<topic>/<type>/<hash>``, CDR payloads, the 33-byte attachment, liveliness tokens) and
subscribes to ``DisparityImage`` with a subscriber token, so the tests check the service against
the contract, not against itself.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass

import numpy as np
import zenoh
import zenoh.ext
from rosbags.typesys import Stores, get_typestore

from vpp_service.rectify import CameraInfo as RawCamera  # a calibration file's content, not the ROS transport

TS = get_typestore(Stores.ROS2_JAZZY)
T = TS.types

HASH = {
    "sensor_msgs/msg/Image": "RIHS01_d31d41a9a4c4bc8eae9be757b0beed306564f7526c88ea6a4588fb9582527d47",
    "sensor_msgs/msg/CompressedImage": TS.hash_rihs01("sensor_msgs/msg/CompressedImage"),
    "sensor_msgs/msg/CameraInfo": "RIHS01_b3dfd68ff46c9d56c80fd3bd4ed22c7a4ddce8c8348f2f59c299e73118e7e275",
    "sensor_msgs/msg/PointCloud2": "RIHS01_9198cabf7da3796ae6fe19c4cb3bdd3525492988c70522628af5daa124bae2b5",
    "stereo_msgs/msg/DisparityImage": "RIHS01_1ec1ff6b5bace919e4544a37f2d96ead9f81783701b7b7a4d97a09325ecf2711",
    "tf2_msgs/msg/TFMessage": TS.hash_rihs01("tf2_msgs/msg/TFMessage"),
}
QOS = "1:2:1,10:,:,:,,"


def dds(ros_type: str) -> str:
    pkg, _, msg = ros_type.split("/")
    return f"{pkg}::msg::dds_::{msg}_"


def key(domain: int, topic: str, ros_type: str) -> str:
    return f"{domain}/{topic.strip('/')}/{dds(ros_type)}/{HASH[ros_type]}"


def header(stamp_ns: int, frame_id: str) -> object:
    sec, nsec = divmod(stamp_ns, 1_000_000_000)
    return T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec), frame_id=frame_id)


def image_msg(img: np.ndarray, stamp_ns: int, frame_id: str, encoding: str | None = None) -> object:
    """An Image of ``img``; the encoding defaults to ``mono8`` for H x W and ``rgb8`` for H x W x 3 arrays."""
    h, w = img.shape[:2]
    if encoding is None:
        encoding = "mono8" if img.ndim == 2 else "rgb8"
    data = np.ascontiguousarray(img).reshape(-1).view(np.uint8)
    return T["sensor_msgs/msg/Image"](
        header=header(stamp_ns, frame_id),
        height=h,
        width=w,
        encoding=encoding,
        is_bigendian=0,
        step=data.size // h,
        data=data,
    )


def compressed_image_msg(
    img: np.ndarray, stamp_ns: int, frame_id: str, codec: str = "jpeg", quality: int = 95
) -> object:
    """A ``CompressedImage`` of an RGB (H x W x 3) or mono8 image as compressed_image_transport writes it.

    The stream holds BGR for a colour image and ``format`` says so: ``"rgb8; jpeg compressed bgr8"``,
    ``"mono8; png compressed "``.
    """
    import cv2

    colour = img.ndim == 3
    params = [cv2.IMWRITE_JPEG_QUALITY, quality] if codec == "jpeg" else [cv2.IMWRITE_PNG_COMPRESSION, 1]
    ok, buf = cv2.imencode(".jpg" if codec == "jpeg" else ".png", img[:, :, ::-1] if colour else img, params)
    assert ok
    fmt = f"rgb8; {codec} compressed bgr8" if colour else f"mono8; {codec} compressed "
    return compressed_bytes_msg(buf.tobytes(), stamp_ns, frame_id, fmt)


def compressed_bytes_msg(data: bytes, stamp_ns: int, frame_id: str, fmt: str) -> object:
    """A ``CompressedImage`` carrying ``data`` as given (e.g. a damaged stream) with ``format`` = ``fmt``."""
    return T["sensor_msgs/msg/CompressedImage"](
        header=header(stamp_ns, frame_id), format=fmt, data=np.frombuffer(data, np.uint8)
    )


def raw_camera_info_msg(stamp_ns: int, frame_id: str, info: RawCamera, **changes: object) -> object:
    """A raw camera's ``CameraInfo``: ``K``, ``D``, ``R``, ``P`` of ``info``, fields replaced by ``changes``."""
    fields = {
        "k": np.asarray(info.k, np.float64).ravel().copy(),
        "d": np.asarray(info.d, np.float64).copy(),
        "r": np.asarray(info.r, np.float64).ravel().copy(),
        "p": np.asarray(info.p, np.float64).ravel().copy(),
        **changes,
    }
    roi = T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
    return T["sensor_msgs/msg/CameraInfo"](
        header=header(stamp_ns, frame_id),
        height=info.height,
        width=info.width,
        distortion_model=info.distortion_model,
        binning_x=0,
        binning_y=0,
        roi=roi,
        **fields,
    )


def camera_info_msg(
    stamp_ns: int, frame_id: str, size: tuple[int, int], *, f: float, cx: float, cy: float, tx: float
) -> object:
    """A rectified CameraInfo with ``P = [f 0 cx tx; 0 f cy 0; 0 0 1 0]``."""
    p = np.array([[f, 0, cx, tx], [0, f, cy, 0], [0, 0, 1.0, 0]])
    return camera_info_from_p(stamp_ns, frame_id, size, p)


def camera_info_from_p(stamp_ns: int, frame_id: str, size: tuple[int, int], p: np.ndarray) -> object:
    """A rectified CameraInfo carrying the 3 x 4 projection ``p`` as given (``K`` = its left 3 x 3, ``R`` = I)."""
    w, h = size
    p = np.asarray(p, np.float64).reshape(3, 4)
    roi = T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
    return T["sensor_msgs/msg/CameraInfo"](
        header=header(stamp_ns, frame_id),
        height=h,
        width=w,
        distortion_model="plumb_bob",
        d=np.zeros(5),
        k=p[:, :3].reshape(-1).copy(),
        r=np.eye(3).reshape(-1),
        p=p.reshape(-1).copy(),
        binning_x=0,
        binning_y=0,
        roi=roi,
    )


def cloud_msg(xyz: np.ndarray, stamp_ns: int, frame_id: str) -> object:
    pts = np.zeros(len(xyz), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4")])
    pts["x"], pts["y"], pts["z"] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    pf = T["sensor_msgs/msg/PointField"]
    fields = [pf(name=n, offset=4 * i, datatype=7, count=1) for i, n in enumerate(("x", "y", "z", "intensity"))]
    return T["sensor_msgs/msg/PointCloud2"](
        header=header(stamp_ns, frame_id),
        height=1,
        width=len(xyz),
        fields=fields,
        is_bigendian=False,
        point_step=16,
        row_step=16 * len(xyz),
        data=pts.view(np.uint8).reshape(-1),
        is_dense=True,
    )


@dataclass
class StereoRig:
    """What the robot publishes: a pair (RGB or gray), its rectified calibration and a cloud in the left optical frame.

    ``p_left``/``p_right`` are the 3 x 4 projections published in camera_info; when None they are built
    from ``f``, ``cx_left``/``cx_right``, ``cy`` and ``tx = -f * baseline`` (right).
    """

    left: np.ndarray
    right: np.ndarray
    f: float
    baseline: float
    cx_left: float
    cx_right: float
    cy: float
    cloud: np.ndarray
    p_left: np.ndarray | None = None
    p_right: np.ndarray | None = None

    @classmethod
    def from_projections(
        cls, left: np.ndarray, right: np.ndarray, p_left: np.ndarray, p_right: np.ndarray, cloud: np.ndarray
    ) -> StereoRig:
        """A rig whose camera_info carries ``p_left``/``p_right`` exactly.

        The scalars are read off them as stereo_image_proc does: ``f = P_right[0]``,
        ``baseline = -P_right[3] / P_right[0]``.
        """
        pl = np.asarray(p_left, np.float64).reshape(3, 4)
        pr = np.asarray(p_right, np.float64).reshape(3, 4)
        return cls(
            left=np.ascontiguousarray(left),
            right=np.ascontiguousarray(right),
            f=float(pr[0, 0]),
            baseline=float(-pr[0, 3] / pr[0, 0]),
            cx_left=float(pl[0, 2]),
            cx_right=float(pr[0, 2]),
            cy=float(pl[1, 2]),
            cloud=cloud,
            p_left=pl,
            p_right=pr,
        )

    def projection(self, right: bool) -> np.ndarray:
        """The 3 x 4 projection published in the left (``right=False``) or right camera_info."""
        given = self.p_right if right else self.p_left
        if given is not None:
            return given
        cx, tx = (self.cx_right, -self.f * self.baseline) if right else (self.cx_left, 0.0)
        return np.array([[self.f, 0, cx, tx], [0, self.f, self.cy, 0], [0, 0, 1.0, 0]])


#: What a rectified rig publishes (topic under the namespace -> type).
RECTIFIED_TOPICS = {
    "left/image_rect": "sensor_msgs/msg/Image",
    "left/camera_info": "sensor_msgs/msg/CameraInfo",
    "right/image_rect": "sensor_msgs/msg/Image",
    "right/camera_info": "sensor_msgs/msg/CameraInfo",
    "points": "sensor_msgs/msg/PointCloud2",
}


class Robot:
    """An rmw_zenoh node ``/stereo/robot`` that publishes a stereo rig and receives disparity.

    ``topics`` (name under the namespace -> type) are its publishers; default :data:`RECTIFIED_TOPICS`.
    """

    def __init__(
        self, session: zenoh.Session, domain: int = 0, namespace: str = "/stereo", topics: dict[str, str] | None = None
    ) -> None:
        self.session, self.domain, self.ns = session, domain, namespace
        self.zid = str(session.zid())
        self.seq: dict[str, int] = {}
        self.tokens = [session.liveliness().declare_token(f"@ros2_lv/{domain}/{self.zid}/0/0/NN/%/%stereo/robot")]
        self.pubs: dict[str, zenoh.Publisher] = {}
        self.topics = dict(RECTIFIED_TOPICS if topics is None else topics)
        for eid, (name, ros_type) in enumerate(self.topics.items(), start=1):
            topic = f"{namespace}/{name}"
            self.pubs[name] = session.declare_publisher(
                key(domain, topic, ros_type), congestion_control=zenoh.CongestionControl.BLOCK
            )
            self.tokens.append(
                session.liveliness().declare_token(
                    f"@ros2_lv/{domain}/{self.zid}/0/{eid}/MP/%/%stereo/robot/{topic.replace('/', '%')}/"
                    f"{dds(ros_type)}/{HASH[ros_type]}/{QOS}"
                )
            )
        self.gid = {name: bytes([i] * 16) for i, name in enumerate(self.topics)}
        # the graph as rmw_zenoh keeps it: a liveliness subscriber with history (PUT = alive, DELETE = gone)
        self._alive: set[str] = set()
        self._lock = threading.Lock()
        self._graph_sub = session.liveliness().declare_subscriber(f"@ros2_lv/{domain}/**", self._on_token, history=True)

    def _on_token(self, sample: zenoh.Sample) -> None:
        with self._lock:
            if sample.kind == zenoh.SampleKind.PUT:
                self._alive.add(str(sample.key_expr))
            else:
                self._alive.discard(str(sample.key_expr))

    def put(self, name: str, msg: object, attachment: bytes | None = None) -> None:
        ros_type = self.topics[name]
        payload = bytes(TS.serialize_cdr(msg, ros_type, little_endian=True))
        self.seq[name] = self.seq.get(name, 0) + 1
        if attachment is None:
            attachment = zenoh.ext.z_serialize(
                (zenoh.ext.Int64(self.seq[name]), zenoh.ext.Int64(time.time_ns()), self.gid[name])
            ).to_bytes()
        self.pubs[name].put(payload, attachment=attachment)

    def publish(self, rig: StereoRig, stamp_ns: int, frame_id: str = "left_optical") -> None:
        h, w = rig.left.shape[:2]
        self.put("left/image_rect", image_msg(rig.left, stamp_ns, frame_id))
        self.put("right/image_rect", image_msg(rig.right, stamp_ns, "right_optical"))
        self.put("left/camera_info", camera_info_from_p(stamp_ns, frame_id, (w, h), rig.projection(right=False)))
        self.put("right/camera_info", camera_info_from_p(stamp_ns, "right_optical", (w, h), rig.projection(right=True)))
        self.put("points", cloud_msg(rig.cloud, stamp_ns, frame_id))

    def publish_tf_static(self, msg: object, transient_local: bool = False) -> None:
        """Put one ``TFMessage`` on ``/tf_static`` (a publisher declared on first use), with an attachment.

        ``transient_local``: the publisher caches the message for subscribers that come later, as
        rmw_zenoh's transient-local publishers do (``PublisherData::make``: an advanced publisher with a
        cache of ``depth`` samples, detectable, with heartbeat miss detection); the session must have
        timestamping on.
        """
        ros_type = "tf2_msgs/msg/TFMessage"
        if "/tf_static" not in self.pubs:
            self.topics["/tf_static"] = ros_type
            self.gid["/tf_static"] = bytes([99] * 16)
            k = key(self.domain, "/tf_static", ros_type)
            if transient_local:
                self.pubs["/tf_static"] = zenoh.ext.declare_advanced_publisher(
                    self.session,
                    k,
                    cache=zenoh.ext.CacheConfig(1),
                    publisher_detection=True,
                    sample_miss_detection=zenoh.ext.MissDetectionConfig(heartbeat=0.5),
                )
            else:
                self.pubs["/tf_static"] = self.session.declare_publisher(k)
        self.put("/tf_static", msg)

    def subscribe_disparity(self, topic: str = "/stereo/disparity") -> zenoh.Subscriber:
        ros_type = "stereo_msgs/msg/DisparityImage"
        self.tokens.append(
            self.session.liveliness().declare_token(
                f"@ros2_lv/{self.domain}/{self.zid}/0/9/MS/%/%stereo/robot/{topic.replace('/', '%')}/"
                f"{dds(ros_type)}/{HASH[ros_type]}/2:2:1,5:,:,:,,"
            )
        )
        return self.session.declare_subscriber(key(self.domain, topic, ros_type), zenoh.handlers.FifoChannel(64))

    def graph(self) -> list[str]:
        """Every rmw_zenoh liveliness token of this domain now alive."""
        with self._lock:
            return sorted(self._alive)

    def wait_for_subscribers(self, names: list[str], timeout: float = 10.0) -> bool:
        """Wait like a lazy publisher until some node declares a subscriber token on each topic."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            toks = self.graph()
            subs = [t for t in toks if "/MS/" in t]
            if all(any(f"/{(self.ns + '/' + n).replace('/', '%')}/" in t for t in subs) for n in names):
                return True
            time.sleep(0.1)
        return False

    def close(self) -> None:
        self._graph_sub.undeclare()
        for t in self.tokens:
            t.undeclare()
        for p in self.pubs.values():
            p.undeclare()


def write_bag(
    path: str,
    storage: str,
    rig: StereoRig,
    stamps: list[int],
    namespace: str = "/stereo",
    *,
    zstd: bool = False,
    compressed: str | None = None,
) -> None:
    """A rosbag2 bag (``storage`` = "mcap" or "sqlite3") with the rig's five topics at each stamp, via rosbags.

    ``zstd``: MCAP chunks compressed with zstd (rosbags' storage compression), as ros2 bag record writes them.
    ``compressed`` ("jpeg" or "png"): the views as ``CompressedImage`` on ``image_rect/compressed`` instead.
    """
    from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer

    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    h, w = rig.left.shape[:2]
    suffix, image_type = (
        ("/compressed", "sensor_msgs/msg/CompressedImage") if compressed else ("", "sensor_msgs/msg/Image")
    )
    types = {
        f"left/image_rect{suffix}": image_type,
        f"right/image_rect{suffix}": image_type,
        "left/camera_info": "sensor_msgs/msg/CameraInfo",
        "right/camera_info": "sensor_msgs/msg/CameraInfo",
        "points": "sensor_msgs/msg/PointCloud2",
    }

    def view(img: np.ndarray, stamp: int, frame_id: str) -> object:
        return compressed_image_msg(img, stamp, frame_id, compressed) if compressed else image_msg(img, stamp, frame_id)

    bag = Writer(path, version=9, storage_plugin=plugin)
    if zstd:
        bag.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    with bag as writer:
        conns = {n: writer.add_connection(f"{namespace}/{n}", t, typestore=TS) for n, t in types.items()}
        for stamp in stamps:
            msgs = {
                f"left/image_rect{suffix}": view(rig.left, stamp, "left_optical"),
                f"right/image_rect{suffix}": view(rig.right, stamp, "right_optical"),
                "left/camera_info": camera_info_from_p(stamp, "left_optical", (w, h), rig.projection(right=False)),
                "right/camera_info": camera_info_from_p(stamp, "right_optical", (w, h), rig.projection(right=True)),
                "points": cloud_msg(rig.cloud, stamp, "left_optical"),
            }
            for i, (n, msg) in enumerate(msgs.items()):
                writer.write(conns[n], stamp + i * 1000, bytes(TS.serialize_cdr(msg, types[n], little_endian=True)))


def tf_message(
    transforms: list[tuple[str, str, tuple[float, float, float], tuple[float, float, float, float]]],
) -> object:
    """A ``tf2_msgs/TFMessage`` of ``(parent, child, translation xyz, rotation quaternion xyzw)`` entries."""
    g = "geometry_msgs/msg/"
    return T["tf2_msgs/msg/TFMessage"](
        transforms=[
            T[g + "TransformStamped"](
                header=header(0, parent),
                child_frame_id=child,
                transform=T[g + "Transform"](translation=T[g + "Vector3"](*xyz), rotation=T[g + "Quaternion"](*q)),
            )
            for parent, child, xyz, q in transforms
        ]
    )
