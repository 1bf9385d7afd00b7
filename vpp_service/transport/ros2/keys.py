"""Names on the ROS 2 graph as ``rmw_zenoh`` spells them: topic keys, types, hashes, QoS, liveliness tokens.

A topic's data travels on the key expression ``<domain_id>/<topic>/<type>/<type_hash>``:

- ``<topic>``: the fully-qualified name without its leading and trailing ``/``;
- ``<type>``: the DDS spelling ``<pkg>::msg::dds_::<Msg>_``;
- ``<type_hash>``: ``RIHS01_`` + 64 hex digits (REP 2011), see :data:`TYPE_HASHES`; Humble
  has no type hashes and its rmw_zenoh writes :data:`HUMBLE_TYPE_HASH` instead (:func:`type_hash`).

Discovery uses liveliness tokens (:func:`node_token`, :func:`entity_token`): without
them a ROS node still receives our data, but ``ros2 topic list`` does not show us
and lazy publishers never start sending. A token is written byte for byte as rmw_zenoh
rebuilds it from its parts (the QoS with default values left out, :meth:`Qos.token`),
because an entity's gid is a hash of that string (:func:`entity_gid`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Annotated, Literal, get_args

import xxhash

from vpp_service.settings import Options, Range

#: The message types this transport reads or writes, by their ROS name.
IMAGE = "sensor_msgs/msg/Image"
COMPRESSED_IMAGE = "sensor_msgs/msg/CompressedImage"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
POINT_CLOUD2 = "sensor_msgs/msg/PointCloud2"
DISPARITY_IMAGE = "stereo_msgs/msg/DisparityImage"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"

#: REP 2011 type-description hashes (identical from Iron through Rolling).
TYPE_HASHES: dict[str, str] = {
    IMAGE: "RIHS01_d31d41a9a4c4bc8eae9be757b0beed306564f7526c88ea6a4588fb9582527d47",
    COMPRESSED_IMAGE: "RIHS01_15640771531571185e2efc8a100baf923961a4d15d5569652e6cb6691e8e371a",
    CAMERA_INFO: "RIHS01_b3dfd68ff46c9d56c80fd3bd4ed22c7a4ddce8c8348f2f59c299e73118e7e275",
    POINT_CLOUD2: "RIHS01_9198cabf7da3796ae6fe19c4cb3bdd3525492988c70522628af5daa124bae2b5",
    DISPARITY_IMAGE: "RIHS01_1ec1ff6b5bace919e4544a37f2d96ead9f81783701b7b7a4d97a09325ecf2711",
    TF_MESSAGE: "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087",
}

#: The type-hash segment of Humble's rmw_zenoh (rmw_publisher_data.cpp / rmw_subscription_data.cpp, humble branch).
HUMBLE_TYPE_HASH = "TypeHashNotSupported"

#: ROS 2 distributions whose rmw_zenoh keys differ only in the type-hash segment.
Distro = Literal["humble", "jazzy", "kilted", "rolling"]
DISTROS: tuple[str, ...] = get_args(Distro)

#: Largest ROS domain id (the DDS port arithmetic limit every rmw accepts).
MAX_DOMAIN_ID = 232

#: What :func:`check_node_name` accepts, in words (option help and errors).
NODE_NAME_RULE = "one token of letters, digits and _ (a ROS node name)"

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


def check_distro(distro: str) -> str:
    """``distro`` when it is one of :data:`DISTROS`.

    Raises
    ------
    ValueError
        Otherwise.
    """
    if distro not in DISTROS:
        raise ValueError(f"ros_distro must be one of {', '.join(DISTROS)}, got {distro!r}")
    return distro


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


def type_hash(ros_type: str, distro: str = "jazzy") -> str:
    """The type-hash segment ``distro``'s rmw_zenoh writes for ``ros_type``.

    Humble: :data:`HUMBLE_TYPE_HASH` for every type; later distros: the type's RIHS01 hash
    (:data:`TYPE_HASHES`).

    Raises
    ------
    ValueError
        An unknown distro, or (after Humble) a type not in :data:`TYPE_HASHES`.
    """
    if check_distro(distro) == "humble":
        dds_type(ros_type)  # still a pkg/msg/Msg name
        return HUMBLE_TYPE_HASH
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


#: rmw_zenoh's QoS defaults (``qos.cpp``, ``RMW_ZENOH_DEFAULT_*``, the same in the Humble, Jazzy, Kilted and
#: Rolling branches): reliable, volatile, keep last, depth 42; deadline, lifespan and lease infinite,
#: liveliness automatic. A token leaves every field equal to its default empty.
RMW_ZENOH_DEFAULT_RELIABILITY = 1
RMW_ZENOH_DEFAULT_DURABILITY = 2
RMW_ZENOH_DEFAULT_HISTORY = 1
RMW_ZENOH_DEFAULT_DEPTH = 42


@dataclass(frozen=True)
class Qos(Options):
    """The QoS fields ``rmw_zenoh`` writes into a liveliness token.

    Deadline, lifespan and liveliness are always rmw_zenoh's defaults (infinite, automatic).

    Attributes
    ----------
    reliability : {1, 2}
        1 reliable, 2 best effort.
    durability : {1, 2}
        1 transient local, 2 volatile.
    history : {1, 2}
        1 keep last, 2 keep all.
    depth : int
        History depth (>= 0; 0 = rmw_zenoh's default, 42).
    """

    reliability: Literal[1, 2] = 1
    durability: Literal[1, 2] = 2
    history: Literal[1, 2] = 1
    depth: Annotated[int, Range(0, 1_000_000)] = 10

    def token(self) -> str:
        """The token's QoS chunk as rmw_zenoh writes it: fields equal to its defaults left empty.

        ``reliability:durability:history,depth:deadline_s,deadline_ns:lifespan_s,lifespan_ns:liveliness,lease_s,lease_ns``
        (``qos_to_keyexpr`` in ``liveliness_utils.cpp``); depth 0 is written as the default 42 it becomes
        (``QoS::best_available_qos``). A default publisher (reliable, volatile, keep last 10): ``::,10:,:,:,,``.
        """
        depth = self.depth or RMW_ZENOH_DEFAULT_DEPTH

        def field(value: int, default: int) -> str:
            return "" if value == default else str(value)

        return (
            f"{field(self.reliability, RMW_ZENOH_DEFAULT_RELIABILITY)}:"
            f"{field(self.durability, RMW_ZENOH_DEFAULT_DURABILITY)}:"
            f"{field(self.history, RMW_ZENOH_DEFAULT_HISTORY)},{field(depth, RMW_ZENOH_DEFAULT_DEPTH)}:,:,:,,"
        )


#: Sensor-data QoS (best effort, volatile, keep last 5): rclcpp's SensorDataQoS.
SENSOR_DATA = Qos(reliability=2, durability=2, history=1, depth=5)
#: The ROS default publisher QoS (reliable, volatile, keep last 10).
DEFAULT_PUBLISHER = Qos(reliability=1, durability=2, history=1, depth=10)
#: Reliable, volatile, keep all (rclcpp's ``KeepAll()``: depth 0): the QoS rmw_zenoh publishes with congestion
#: control BLOCK.
RELIABLE_KEEP_ALL = Qos(reliability=1, durability=2, history=2, depth=0)
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


@dataclass(frozen=True)
class EntityKey:
    """What a publisher or subscriber token says about its topic (see :func:`parse_entity_token`).

    Attributes
    ----------
    kind : {"MP", "MS"}
        Publisher or subscriber.
    topic : str
        Fully-qualified topic name (demangled).
    dds_type : str
        Type segment, ``pkg::msg::dds_::Msg_``.
    type_hash : str
        Type-hash segment (``RIHS01_...`` or :data:`HUMBLE_TYPE_HASH`).
    """

    kind: str
    topic: str
    dds_type: str
    type_hash: str


def parse_entity_token(token_key: str, domain_id: int) -> EntityKey | None:
    """The topic of a publisher (``MP``) or subscriber (``MS``) token of ``domain_id``; None for anything else.

    The parts are split on ``/`` as ``Entity::make(keyexpr)`` in ``liveliness_utils.cpp`` does: admin space,
    domain, zid, nid, id, kind, enclave, namespace, node, topic, type, hash, QoS (13 parts, none empty).
    """
    parts = token_key.split("/")
    if len(parts) < 13 or parts[0] != "@ros2_lv" or parts[1] != str(domain_id) or parts[5] not in ("MP", "MS"):
        return None
    if any(not p for p in parts[:12]):
        return None
    return EntityKey(parts[5], parts[9].replace("%", "/"), parts[10], parts[11])


def entity_gid(token_key: str) -> bytes:
    """The 16-byte gid rmw_zenoh gives the entity whose liveliness key is ``token_key``.

    XXH3-128 (seed 0) of the key string, then the low 64 bits and the high 64 bits, each little
    endian (``Entity::Entity`` in ``liveliness_utils.cpp``: ``simplified_XXH3_128bits`` and two
    ``memcpy``). It is the gid of every sample's attachment and of ``ros2 topic info -v``.
    """
    return int(xxhash.xxh3_128_intdigest(token_key.encode())).to_bytes(16, "little")


__all__ = [
    "CAMERA_INFO",
    "COMPRESSED_IMAGE",
    "DEFAULT_PUBLISHER",
    "DISPARITY_IMAGE",
    "DISTROS",
    "HUMBLE_TYPE_HASH",
    "IMAGE",
    "MAX_DOMAIN_ID",
    "POINT_CLOUD2",
    "RELIABLE_KEEP_ALL",
    "RMW_ZENOH_DEFAULT_DEPTH",
    "RMW_ZENOH_DEFAULT_DURABILITY",
    "RMW_ZENOH_DEFAULT_HISTORY",
    "RMW_ZENOH_DEFAULT_RELIABILITY",
    "SENSOR_DATA",
    "TF_MESSAGE",
    "TF_STATIC",
    "TYPE_HASHES",
    "Distro",
    "EntityKey",
    "NodeName",
    "Qos",
    "check_distro",
    "check_domain",
    "check_namespace",
    "check_node_name",
    "dds_type",
    "entity_gid",
    "entity_token",
    "fully_qualified",
    "mangle",
    "node_token",
    "parse_entity_token",
    "topic_key",
    "type_hash",
]
