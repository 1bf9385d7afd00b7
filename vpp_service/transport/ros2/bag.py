"""rosbag2 bags (``.db3`` sqlite3 and ``.mcap``) read and written with ``rosbags``.

:func:`read_bag` yields the raw CDR messages of chosen topics in log-time order, as
``ros2 bag play`` sends them; :class:`BagWriter` records CDR messages into a new bag
(MCAP by default, which Foxglove, rviz and ``ros2 bag`` open). A bag is a folder with
``metadata.yaml`` or a single ``.db3`` / ``.mcap`` file; the path comes from the
configuration only, never from message content.

A written bag carries what ``ros2 bag record`` writes, so ``ros2 bag play`` republishes
each topic with the QoS it was offered with: per topic the publisher's offered QoS
profile (:func:`offered_qos`), and the ROS distribution it is for (``ros_distro``), in
that distribution's metadata form (:data:`DISTRO_VERSIONS`).
"""

from __future__ import annotations

import logging
import sqlite3
from collections.abc import Collection, Iterator
from pathlib import Path, PurePath
from typing import TYPE_CHECKING, Any, Literal

from vpp_service.transport.ros2.bag_damage import BagDamage, OnDamage
from vpp_service.transport.ros2.bag_message import BagMessage
from vpp_service.transport.ros2.keys import DEFAULT_PUBLISHER, Qos
from vpp_service.transport.ros2.messages import typestore

if TYPE_CHECKING:
    from rosbags.interfaces import Qos as BagQos

log = logging.getLogger(__name__)

#: Storage formats a bag can be written in.
Storage = Literal["mcap", "sqlite3"]
#: ROS distributions a bag can be written for.
RosDistro = Literal["humble", "jazzy"]
#: The rosbag2 metadata version written per distribution. Jazzy's recorder writes 9
#: (``offered_qos_profiles`` a YAML list, enums by name: ``keep_last``, ``reliable``). Humble's
#: writes 5 with the profiles as one YAML string, enums as integers; ``rosbags`` writes 8 at the
#: oldest, whose profiles have exactly that string form (its other additions Humble's reader skips).
DISTRO_VERSIONS: dict[str, Literal[8, 9]] = {"humble": 8, "jazzy": 9}
#: ``RMW_DURATION_INFINITE`` (``{9223372036, 854775807}``): deadline, lifespan and liveliness lease
#: of a publisher that leaves them unset, as an rmw_zenoh graph reports it (its default QoS).
INFINITE_S, INFINITE_NS = 9_223_372_036, 854_775_807


def check_bag_path(path: str | Path) -> Path:
    """``path`` when it is an existing bag folder (with ``metadata.yaml``) or ``.db3`` / ``.mcap`` file.

    Raises
    ------
    FileNotFoundError
        Nothing there.
    ValueError
        Neither a bag folder nor a bag file.
    """
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"rosbag: no such file or folder: {p}")
    if p.is_dir() and not (p / "metadata.yaml").is_file():
        raise ValueError(f"rosbag: {p} is a folder without metadata.yaml")
    if p.is_file() and p.suffix not in (".db3", ".mcap"):
        raise ValueError(f"rosbag: {p} is neither a .db3 nor a .mcap file")
    return p


def _bag_info(folder: Path) -> dict[str, Any]:
    """The ``rosbag2_bagfile_information`` mapping of a bag folder's ``metadata.yaml``."""
    from ruamel.yaml import YAML  # rosbags' own YAML reader (a dependency of rosbags)

    meta = folder / "metadata.yaml"
    try:
        info = YAML(typ="safe").load(meta.read_text())["rosbag2_bagfile_information"]
        if not isinstance(info, dict):
            raise TypeError("rosbag2_bagfile_information is not a mapping")
        return info
    except Exception as exc:  # noqa: BLE001 - OSError, YAMLError, KeyError, TypeError: metadata.yaml does not hold
        raise ValueError(f"rosbag: {meta} cannot be read ({type(exc).__name__}: {exc})") from None


def _bag_files(path: Path) -> list[Path] | None:
    """The storage files of a bag, in recording order (None: a compressed bag folder, read by rosbags)."""
    if path.is_file():
        return [path]
    info = _bag_info(path)
    try:
        mode = str(info.get("compression_mode") or "").lower()
        files = [path / PurePath(str(x)).name for x in info["relative_file_paths"]]
    except (KeyError, TypeError) as exc:
        raise ValueError(f"rosbag: {path / 'metadata.yaml'}: no list of files ({exc})") from None
    if mode not in ("", "none"):
        return None
    if missing := [str(f) for f in files if not f.is_file()]:
        raise ValueError(f"rosbag: {path}: files named in metadata.yaml are missing: {missing}")
    if odd := [str(f) for f in files if f.suffix not in (".db3", ".mcap")]:
        raise ValueError(f"rosbag: {path}: files of an unsupported storage: {odd}")
    return files


def bag_topics(path: str | Path) -> dict[str, str]:
    """Topic -> message type of every connection in the bag.

    A bag folder's come from its ``metadata.yaml``; an ``.mcap`` file's from its summary,
    or when that is gone (a cut file) from a pass over its readable records; a ``.db3``
    file's from its ``topics`` table.

    Raises
    ------
    FileNotFoundError, ValueError
        Not a bag (see :func:`check_bag_path`), or its topics cannot be read.
    """
    from vpp_service.transport.ros2.db3_reader import db3_topics
    from vpp_service.transport.ros2.mcap_reader import McapWalk

    p = check_bag_path(path)
    if p.is_dir():
        try:
            topics = _bag_info(p)["topics_with_message_count"]
            return {str(t["topic_metadata"]["name"]): str(t["topic_metadata"]["type"]) for t in topics}
        except (KeyError, TypeError) as exc:
            raise ValueError(f"rosbag: {p / 'metadata.yaml'}: no list of topics ({exc})") from None
    if p.suffix == ".db3":
        return db3_topics(p)
    walk = McapWalk(p, topics=())
    found = walk.summary_topics()
    if found is None:
        for _ in walk:
            pass
        found = {topic: walk.schemas.get(sid, "") for topic, sid in walk.channels.values()}
    return found


def _log_damage(damage: BagDamage) -> None:
    log.warning("rosbag: damaged: %s", damage)


def read_bag(
    path: str | Path, topics: Collection[str] | None = None, on_damage: OnDamage | None = None
) -> Iterator[BagMessage]:
    """The bag's messages on ``topics`` (None = all), in log-time order.

    A damaged bag (cut short, garbage in a chunk or a page) plays every message that can
    be read; each damaged place, its cause and where it is go to ``on_damage`` (None:
    logged as a warning) and reading goes on past it where the format allows
    (:mod:`~vpp_service.transport.ros2.mcap_reader`, :mod:`~vpp_service.transport.ros2.db3_reader`).
    A bag folder with ``compression_mode`` set is read by rosbags, without that.

    Raises
    ------
    FileNotFoundError, ValueError
        Not a bag (see :func:`check_bag_path`), or not one message on ``topics`` could be
        read from a damaged bag (the error names the file and the first damage).
    """
    from vpp_service.transport.ros2.db3_reader import Db3Rows
    from vpp_service.transport.ros2.mcap_reader import McapWalk

    p = check_bag_path(path)
    files = _bag_files(p)
    if files is None:
        yield from _read_with_rosbags(p, topics)
        return
    report = on_damage or _log_damage
    first: list[BagDamage] = []

    def note(damage: BagDamage) -> None:
        first[:] = first or [damage]
        report(damage)

    played = 0
    for f in files:
        for m in McapWalk(f, topics, note) if f.suffix == ".mcap" else Db3Rows(f, topics, note):
            played += 1
            yield m
    if not played and first:
        raise ValueError(f"rosbag: {p}: nothing readable on the chosen topics; first damage: {first[0]}")


def _read_with_rosbags(path: Path, topics: Collection[str] | None) -> Iterator[BagMessage]:
    """A bag rosbags reads for us (a compressed bag folder)."""
    from rosbags.rosbag2 import Reader, ReaderError

    try:
        with Reader(path) as reader:
            conns = [c for c in reader.connections if topics is None or c.topic in topics]
            if not conns:
                return
            for conn, ts, raw in reader.messages(connections=conns):
                yield BagMessage(conn.topic, conn.msgtype, int(ts), raw)
    except ReaderError as exc:
        raise ValueError(f"rosbag: {path}: {exc}") from None


def offered_qos(qos: Qos) -> BagQos:
    """``qos`` as a rosbag2 offered QoS profile: the four policies given, the rest as an rmw_zenoh graph reports them.

    Deadline, lifespan and liveliness lease are infinite, liveliness ``automatic`` and
    ``avoid_ros_namespace_conventions`` false: the rmw_zenoh defaults a subscriber (``ros2 bag
    record``) reads for a publisher token that leaves them empty, as ours do (:meth:`Qos.token`).
    The enum values of :class:`~vpp_service.transport.ros2.keys.Qos` are the rmw ones.
    """
    from rosbags.interfaces import Qos as BagQos
    from rosbags.interfaces import QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime

    infinite = QosTime(INFINITE_S, INFINITE_NS)
    return BagQos(
        history=QosHistory(qos.history),
        depth=qos.depth,
        reliability=QosReliability(qos.reliability),
        durability=QosDurability(qos.durability),
        deadline=infinite,
        lifespan=infinite,
        liveliness=QosLiveliness.AUTOMATIC,
        liveliness_lease_duration=infinite,
        avoid_ros_namespace_conventions=False,
    )


def _with_distro(metadata: str, ros_distro: str, key: str | None) -> str:
    """The metadata YAML ``metadata`` with ``ros_distro`` set (under ``key`` when given)."""
    from io import StringIO

    from ruamel.yaml import YAML

    yaml = YAML(typ="safe")
    yaml.default_flow_style = False
    doc = yaml.load(metadata)
    (doc[key] if key is not None else doc)["ros_distro"] = ros_distro
    out = StringIO()
    yaml.dump(doc, out)
    return out.getvalue() if key is not None else out.getvalue().strip()


class BagWriter:
    """Record CDR messages into a new bag.

    Parameters
    ----------
    path : str or Path
        The bag folder to create (must not exist).
    storage : {"mcap", "sqlite3"}
        Storage format.
    ros_distro : {"humble", "jazzy"}
        The distribution the bag is for: its metadata version (:data:`DISTRO_VERSIONS`) and
        ``ros_distro`` (in ``metadata.yaml`` and the copy inside the storage file).
    """

    def __init__(self, path: str | Path, storage: Storage = "mcap", ros_distro: RosDistro = "jazzy") -> None:
        from rosbags.rosbag2 import StoragePlugin, Writer

        p = Path(path)
        if p.exists():
            raise FileExistsError(f"rosbag: {p} exists already (a recording never overwrites)")
        if storage not in ("mcap", "sqlite3"):
            raise ValueError(f"storage must be 'mcap' or 'sqlite3', got {storage!r}")
        if ros_distro not in DISTRO_VERSIONS:
            raise ValueError(f"ros_distro must be one of {', '.join(DISTRO_VERSIONS)}, got {ros_distro!r}")
        plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
        self.path = p
        self.ros_distro = ros_distro
        self._writer = Writer(p, version=DISTRO_VERSIONS[ros_distro], storage_plugin=plugin)
        self._writer.open()
        # rosbags writes ros_distro "rosbags" into the storage file too (the metadata copy, and sqlite3's
        # schema table, which rosbag2 reads when metadata.yaml is missing): the real one instead
        storage_writer = self._writer.storage
        assert storage_writer is not None  # open
        close_storage = storage_writer.close

        def close_with_distro(version: int, metadata: str) -> None:
            conn = getattr(storage_writer, "conn", None)
            if isinstance(conn, sqlite3.Connection):
                conn.execute("UPDATE schema SET ros_distro = ?", (ros_distro,))
            close_storage(version, _with_distro(metadata, ros_distro, None))

        storage_writer.close = close_with_distro  # type: ignore[method-assign]  # one instance's close, wrapped
        self._conns: dict[str, object] = {}
        self.written = 0

    def write(
        self, topic: str, ros_type: str, log_time_ns: int, data: bytes | bytearray, qos: Qos = DEFAULT_PUBLISHER
    ) -> None:
        """Append one message; the topic's connection (with ``qos`` as its offered profile) is added on its first."""
        from rosbags.interfaces import Connection

        conn = self._conns.get(topic)
        if conn is None:
            conn = self._writer.add_connection(
                topic, ros_type, typestore=typestore(), offered_qos_profiles=[offered_qos(qos)]
            )
            self._conns[topic] = conn
        assert isinstance(conn, Connection)
        self._writer.write(conn, int(log_time_ns), data if isinstance(data, bytes) else memoryview(data))
        self.written += 1

    def close(self) -> None:
        """Finish the bag (writes ``metadata.yaml``, with the real ``ros_distro``)."""
        self._writer.close()
        meta = self._writer.metapath
        meta.write_text(_with_distro(meta.read_text("utf8"), self.ros_distro, "rosbag2_bagfile_information"), "utf8")


__all__ = [
    "DISTRO_VERSIONS",
    "BagMessage",
    "BagWriter",
    "RosDistro",
    "Storage",
    "bag_topics",
    "check_bag_path",
    "offered_qos",
    "read_bag",
]
