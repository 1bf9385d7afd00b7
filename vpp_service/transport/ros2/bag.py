"""rosbag2 bags (``.db3`` sqlite3 and ``.mcap``) read and written with ``rosbags``.

:func:`read_bag` yields the raw CDR messages of chosen topics in log-time order, as
``ros2 bag play`` sends them; :class:`BagWriter` records CDR messages into a new bag
(MCAP by default, which Foxglove, rviz and ``ros2 bag`` open). A bag is a folder with
``metadata.yaml`` or a single ``.db3`` / ``.mcap`` file; the path comes from the
configuration only, never from message content.
"""

from __future__ import annotations

from collections.abc import Collection, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from vpp_service.transport.ros2.messages import typestore

#: Storage formats a bag can be written in.
Storage = Literal["mcap", "sqlite3"]


@dataclass(frozen=True)
class BagMessage:
    """One recorded message.

    Attributes
    ----------
    topic : str
        Fully-qualified topic name.
    ros_type : str
        ``pkg/msg/Msg``.
    log_time_ns : int
        Recording time of the message, ns.
    data : bytes
        The CDR payload.
    """

    topic: str
    ros_type: str
    log_time_ns: int
    data: bytes


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


def bag_topics(path: str | Path) -> dict[str, str]:
    """Topic -> message type of every connection in the bag."""
    from rosbags.rosbag2 import Reader

    with Reader(check_bag_path(path)) as reader:
        return {c.topic: c.msgtype for c in reader.connections}


def read_bag(path: str | Path, topics: Collection[str] | None = None) -> Iterator[BagMessage]:
    """The bag's messages on ``topics`` (None = all), in log-time order.

    Raises
    ------
    FileNotFoundError, ValueError
        Not a bag (see :func:`check_bag_path`), or the bag cannot be read.
    """
    from rosbags.rosbag2 import Reader, ReaderError

    try:
        with Reader(check_bag_path(path)) as reader:
            conns = [c for c in reader.connections if topics is None or c.topic in topics]
            if not conns:
                return
            for conn, ts, raw in reader.messages(connections=conns):
                yield BagMessage(conn.topic, conn.msgtype, int(ts), raw)
    except ReaderError as exc:
        raise ValueError(f"rosbag: {path}: {exc}") from None


class BagWriter:
    """Record CDR messages into a new bag.

    Parameters
    ----------
    path : str or Path
        The bag folder to create (must not exist).
    storage : {"mcap", "sqlite3"}
        Storage format.
    """

    def __init__(self, path: str | Path, storage: Storage = "mcap") -> None:
        from rosbags.rosbag2 import StoragePlugin, Writer

        p = Path(path)
        if p.exists():
            raise FileExistsError(f"rosbag: {p} exists already (a recording never overwrites)")
        if storage not in ("mcap", "sqlite3"):
            raise ValueError(f"storage must be 'mcap' or 'sqlite3', got {storage!r}")
        plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
        self.path = p
        self._writer = Writer(p, version=Writer.VERSION_LATEST, storage_plugin=plugin)
        self._writer.open()
        self._conns: dict[str, object] = {}
        self.written = 0

    def write(self, topic: str, ros_type: str, log_time_ns: int, data: bytes | bytearray) -> None:
        """Append one message (its connection is added on the topic's first message)."""
        from rosbags.interfaces import Connection

        conn = self._conns.get(topic)
        if conn is None:
            conn = self._writer.add_connection(topic, ros_type, typestore=typestore())
            self._conns[topic] = conn
        assert isinstance(conn, Connection)
        self._writer.write(conn, int(log_time_ns), data if isinstance(data, bytes) else memoryview(data))
        self.written += 1

    def close(self) -> None:
        """Finish the bag (writes ``metadata.yaml``)."""
        self._writer.close()


__all__ = ["BagMessage", "BagWriter", "Storage", "bag_topics", "check_bag_path", "read_bag"]
