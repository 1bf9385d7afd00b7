"""Names on the ROS 2 graph as ``rmw_zenoh`` spells them: topic keys, types, hashes, QoS, liveliness tokens.

A topic's data travels on the key expression ``<domain_id>/<topic>/<type>/<type_hash>``:

- ``<topic>``: the fully-qualified name without its leading and trailing ``/``;
- ``<type>``: the DDS spelling ``<pkg>::msg::dds_::<Msg>_``;
- ``<type_hash>``: ``RIHS01_`` + 64 hex digits (REP 2011), see :data:`TYPE_HASHES`.

Discovery uses liveliness tokens (:func:`node_token`, :func:`entity_token`): without
them a ROS node still receives our data, but ``ros2 topic list`` does not show us
and lazy publishers never start sending.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Literal

#: The message types this transport reads or writes, by their ROS name.
IMAGE = "sensor_msgs/msg/Image"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
POINT_CLOUD2 = "sensor_msgs/msg/PointCloud2"
DISPARITY_IMAGE = "stereo_msgs/msg/DisparityImage"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"

#: REP 2011 type-description hashes (identical from Iron through Rolling).
TYPE_HASHES: dict[str, str] = {
    IMAGE: "RIHS01_d31d41a9a4c4bc8eae9be757b0beed306564f7526c88ea6a4588fb9582527d47",
    CAMERA_INFO: "RIHS01_b3dfd68ff46c9d56c80fd3bd4ed22c7a4ddce8c8348f2f59c299e73118e7e275",
    POINT_CLOUD2: "RIHS01_9198cabf7da3796ae6fe19c4cb3bdd3525492988c70522628af5daa124bae2b5",
    DISPARITY_IMAGE: "RIHS01_1ec1ff6b5bace919e4544a37f2d96ead9f81783701b7b7a4d97a09325ecf2711",
    TF_MESSAGE: "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087",
}

#: Largest ROS domain id (the DDS port arithmetic limit every rmw accepts).
MAX_DOMAIN_ID = 232

_NAME_RE = re.compile(r"^(/[A-Za-z_][A-Za-z0-9_]*)+$")
_TOKEN_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_TYPE_RE = re.compile(r"^([A-Za-z_][A-Za-z0-9_]*)/msg/([A-Za-z][A-Za-z0-9_]*)$")


def check_domain(domain_id: int) -> int:
    """``domain_id`` when it is an int in ``[0, MAX_DOMAIN_ID]``.

    Raises
    ------
    ValueError
        Otherwise.
    """
    if isinstance(domain_id, bool) or not isinstance(domain_id, int) or not 0 <= domain_id <= MAX_DOMAIN_ID:
        raise ValueError(f"domain_id must be an integer in [0, {MAX_DOMAIN_ID}], got {domain_id!r}")
    return domain_id


def check_namespace(namespace: str) -> str:
    """A namespace in canonical form: ``"/"`` or ``"/a/b"`` (no trailing ``/``).

    Raises
    ------
    ValueError
        Not an absolute ROS name made of ``[A-Za-z0-9_]`` tokens.
    """
    if namespace == "/":
        return namespace
    ns = namespace.rstrip("/") if len(namespace) > 1 else namespace
    if not _NAME_RE.match(ns):
        raise ValueError(f"namespace must look like '/stereo' (letters, digits, _), got {namespace!r}")
    return ns


def check_node_name(name: str) -> str:
    """``name`` when it is a valid ROS node name (one token).

    Raises
    ------
    ValueError
        Otherwise.
    """
    if not _TOKEN_RE.match(name):
        raise ValueError(f"node name must be one token of letters, digits and _, got {name!r}")
    return name


def fully_qualified(namespace: str, name: str) -> str:
    """The fully-qualified topic name: ``name`` if absolute, else ``namespace/name``.

    Raises
    ------
    ValueError
        Invalid namespace or name (``//``, characters outside ``[A-Za-z0-9_/]``, ...).
    """
    ns = check_namespace(namespace)
    fq = name if name.startswith("/") else (f"/{name}" if ns == "/" else f"{ns}/{name}")
    if not _NAME_RE.match(fq):
        raise ValueError(f"topic name must look like 'left/image_rect' (letters, digits, _, /), got {name!r}")
    return fq


def dds_type(ros_type: str) -> str:
    """``pkg/msg/Msg`` -> ``pkg::msg::dds_::Msg_`` (the type segment of keys and tokens).

    Raises
    ------
    ValueError
        Not a ``pkg/msg/Msg`` name.
    """
    m = _TYPE_RE.match(ros_type)
    if m is None:
        raise ValueError(f"message type must look like 'pkg/msg/Msg', got {ros_type!r}")
    return f"{m.group(1)}::msg::dds_::{m.group(2)}_"


def type_hash(ros_type: str) -> str:
    """The RIHS01 hash of one of the supported types (:data:`TYPE_HASHES`).

    Raises
    ------
    ValueError
        A type not in :data:`TYPE_HASHES`.
    """
    try:
        return TYPE_HASHES[ros_type]
    except KeyError:
        raise ValueError(f"no type hash known for {ros_type!r}; known: {', '.join(TYPE_HASHES)}") from None


def topic_key(domain_id: int, topic: str, ros_type: str, hash_: str | None = None) -> str:
    """The data key expression of a fully-qualified ``topic``.

    Parameters
    ----------
    domain_id : int
        ROS domain id.
    topic : str
        Fully-qualified topic name (``/stereo/disparity``).
    ros_type : str
        ``pkg/msg/Msg``.
    hash_ : str or None
        Type-hash segment; None = the type's RIHS01 hash. A subscriber passes ``"*"``
        to receive from publishers of any hash (Humble publishes ``TypeHashNotSupported``).

    Examples
    --------
    >>> topic_key(0, "/stereo/disparity", "stereo_msgs/msg/DisparityImage")[:55]
    '0/stereo/disparity/stereo_msgs::msg::dds_::DisparityIma'
    """
    check_domain(domain_id)
    if not _NAME_RE.match(topic):
        raise ValueError(f"topic must be a fully-qualified ROS name, got {topic!r}")
    return f"{domain_id}/{topic.strip('/')}/{dds_type(ros_type)}/{hash_ or type_hash(ros_type)}"


def mangle(name: str) -> str:
    """A name as a single liveliness-key chunk: every ``/`` becomes ``%``, empty becomes ``%``."""
    return name.replace("/", "%") if name else "%"


@dataclass(frozen=True)
class Qos:
    """The QoS fields ``rmw_zenoh`` writes into a liveliness token.

    Attributes
    ----------
    reliability : {1, 2}
        1 reliable, 2 best effort.
    durability : {1, 2}
        1 transient local, 2 volatile.
    history : {1, 2}
        1 keep last, 2 keep all.
    depth : int
        History depth (>= 0).
    """

    reliability: Literal[1, 2] = 1
    durability: Literal[1, 2] = 2
    history: Literal[1, 2] = 1
    depth: int = 10

    def __post_init__(self) -> None:
        for name in ("reliability", "durability", "history"):
            if getattr(self, name) not in (1, 2):
                raise ValueError(f"{name} must be 1 or 2, got {getattr(self, name)!r}")
        if isinstance(self.depth, bool) or not isinstance(self.depth, int) or not 0 <= self.depth <= 1_000_000:
            raise ValueError(f"depth must be an integer in [0, 1000000], got {self.depth!r}")

    def token(self) -> str:
        """``reliability:durability:history,depth:,:,:,,`` (deadline, lifespan, liveliness left default)."""
        return f"{self.reliability}:{self.durability}:{self.history},{self.depth}:,:,:,,"


#: Sensor-data QoS (best effort, volatile, keep last 5): what our subscribers declare.
SENSOR_DATA = Qos(reliability=2, durability=2, history=1, depth=5)
#: The ROS default publisher QoS (reliable, volatile, keep last 10): what our publishers declare.
DEFAULT_PUBLISHER = Qos(reliability=1, durability=2, history=1, depth=10)
#: tf2_ros' static listener QoS (reliable, transient local, keep last 100): our ``/tf_static`` subscriber.
TF_STATIC = Qos(reliability=1, durability=1, history=1, depth=100)


@dataclass(frozen=True)
class NodeName:
    """Where a node sits on the graph.

    Attributes
    ----------
    domain_id : int
        ROS domain id.
    zid : str
        The Zenoh session id as a string.
    nid : int
        Node id, unique within the session.
    namespace : str
        Node namespace (``/stereo``).
    name : str
        Node name (one token).
    enclave : str
        Security enclave (empty = none).
    """

    domain_id: int
    zid: str
    nid: int
    namespace: str
    name: str
    enclave: str = ""

    def __post_init__(self) -> None:
        check_domain(self.domain_id)
        check_namespace(self.namespace)
        check_node_name(self.name)
        if not self.zid or "/" in self.zid or isinstance(self.nid, bool) or self.nid < 0:
            raise ValueError(f"zid must be a non-empty chunk and nid >= 0, got {self.zid!r}, {self.nid!r}")

    def _tail(self) -> str:
        ns = "" if self.namespace == "/" else self.namespace
        return f"{mangle(self.enclave)}/{mangle(ns)}/{self.name}"


def node_token(node: NodeName) -> str:
    """``@ros2_lv/<domain>/<zid>/<nid>/<nid>/NN/<enclave>/<namespace>/<node_name>``."""
    return f"@ros2_lv/{node.domain_id}/{node.zid}/{node.nid}/{node.nid}/NN/{node._tail()}"


def entity_token(
    node: NodeName,
    eid: int,
    kind: Literal["MP", "MS"],
    topic: str,
    ros_type: str,
    *,
    qos: Qos,
    hash_: str | None = None,
) -> str:
    """The liveliness key of a publisher (``MP``) or subscriber (``MS``) of ``node``.

    ``@ros2_lv/<domain>/<zid>/<nid>/<eid>/MP|MS/<enclave>/<namespace>/<node>/<topic>/<type>/<hash>/<qos>``
    with the topic mangled (``/stereo/disparity`` -> ``%stereo%disparity``).
    """
    if kind not in ("MP", "MS"):
        raise ValueError(f"kind must be 'MP' or 'MS', got {kind!r}")
    if isinstance(eid, bool) or not isinstance(eid, int) or eid < 0:
        raise ValueError(f"eid must be an integer >= 0, got {eid!r}")
    if not _NAME_RE.match(topic):
        raise ValueError(f"topic must be a fully-qualified ROS name, got {topic!r}")
    return (
        f"@ros2_lv/{node.domain_id}/{node.zid}/{node.nid}/{eid}/{kind}/{node._tail()}/"
        f"{mangle(topic)}/{dds_type(ros_type)}/{hash_ or type_hash(ros_type)}/{qos.token()}"
    )


__all__ = [
    "CAMERA_INFO",
    "DEFAULT_PUBLISHER",
    "DISPARITY_IMAGE",
    "IMAGE",
    "MAX_DOMAIN_ID",
    "POINT_CLOUD2",
    "SENSOR_DATA",
    "TF_MESSAGE",
    "TF_STATIC",
    "TYPE_HASHES",
    "NodeName",
    "Qos",
    "check_domain",
    "check_namespace",
    "check_node_name",
    "dds_type",
    "entity_token",
    "fully_qualified",
    "mangle",
    "node_token",
    "topic_key",
    "type_hash",
]
