"""sqlite3 bags (rosbag2's ``.db3``) read row by row, so damage costs only the rows it touches.

The file is opened read-only and immutable (with apsw, as rosbags does) and
``writable_schema`` on, which lets SQLite read a file shorter than its header says
(otherwise it refuses the whole database); a short file is seen through a VFS that
ends it at its last whole page (SQLite's pager takes a short read as zeros: Python's
sqlite3 on SQLite 3.40 returned such a zero-filled row without an error).
The keys (log time, row id, topic) of the chosen topics are read first, sorted by log
time; when the table itself breaks off, the keys come from a row-id scan that stops at
the break and probes past it. Then each row's data is read alone: a row SQLite refuses
is skipped and reported through ``on_damage``
(:mod:`~vpp_service.transport.ros2.bag_damage`): ``bag.truncated`` when the file is
shorter than its header says, ``bag.corrupt_row`` otherwise. SQLite has no checksums:
garbage inside a message's bytes that leaves the database's structure intact cannot
be seen.
"""

from __future__ import annotations

import threading
from collections.abc import Collection, Iterator
from pathlib import Path
from urllib.parse import quote

import apsw

from vpp_service.transport.ros2.bag_damage import BagDamage, OnDamage, ignore_damage
from vpp_service.transport.ros2.bag_message import BagMessage

SQLITE_MAGIC = b"SQLite format 3\x00"
#: Probes past a break in the messages table (row ids break + 1, + 2, + 4, ...).
_PROBES = 40


#: Name of the VFS that ends a file at its last whole page.
_WHOLE_PAGES = "vpp_whole_pages"


class _WholePagesFile(apsw.VFSFile):
    """A database file whose size is rounded down to whole pages (reads go to the default VFS)."""

    def __init__(self, filename: str | apsw.URIFilename | None, flags: list[int]) -> None:
        super().__init__("", filename, flags)
        head = super().xRead(100, 0)
        size = int.from_bytes(head[16:18], "big") if len(head) == 100 else 0
        self._page = 65536 if size == 1 else max(size, 512)

    def xFileSize(self) -> int:
        size = super().xFileSize()
        return size - size % self._page


class _WholePagesVFS(apsw.VFS):
    def __init__(self) -> None:
        super().__init__(_WHOLE_PAGES, "")

    def xOpen(self, name: str | apsw.URIFilename | None, flags: list[int]) -> apsw.VFSFile:
        return _WholePagesFile(name, flags)


_vfs_lock = threading.Lock()
_vfs: list[_WholePagesVFS] = []


def _whole_pages_vfs() -> None:
    """Register the VFS once per process (apsw keeps it while this module holds it)."""
    with _vfs_lock:
        if not _vfs:
            _vfs.append(_WholePagesVFS())


def _short_by(path: Path) -> int:
    """Bytes the file lacks against the page count of its header (0: full length, or the count is not valid)."""
    with path.open("rb") as f:
        head = f.read(100)
        size = f.seek(0, 2)
    if len(head) < 100 or not head.startswith(SQLITE_MAGIC):
        raise ValueError(f"rosbag: {path}: not an sqlite3 database (its first bytes are not the SQLite magic)")
    page_size = int.from_bytes(head[16:18], "big")
    page_size = 65536 if page_size == 1 else page_size
    if head[24:28] != head[92:96]:  # "version-valid-for" differs: the page count is stale
        return 0
    return max(0, int.from_bytes(head[28:32], "big") * page_size - size)


def _connect(path: Path, short: bool) -> apsw.Connection:
    vfs = None
    if short:
        _whole_pages_vfs()
        vfs = _WHOLE_PAGES
    conn = apsw.Connection(
        f"file:{quote(str(path.resolve()))}?immutable=1",
        flags=apsw.SQLITE_OPEN_READONLY | apsw.SQLITE_OPEN_URI,
        vfs=vfs,
    )
    conn.execute("PRAGMA writable_schema = ON")  # read what a short file holds; the connection cannot write
    return conn


def db3_topics(path: str | Path) -> dict[str, str]:
    """Topic -> message type of the ``topics`` table.

    Raises
    ------
    ValueError
        Not an sqlite3 database, or its topics cannot be read.
    """
    p = Path(path)
    conn = _connect(p, bool(_short_by(p)))
    try:
        return {name: ros_type for _, name, ros_type in _topic_rows(conn, p)}
    finally:
        conn.close()


def _topic_rows(conn: apsw.Connection, path: Path) -> list[tuple[int, str, str]]:
    try:
        return [(int(i), str(n), str(t)) for i, n, t in conn.execute("SELECT id, name, type FROM topics")]
    except apsw.Error as exc:
        raise ValueError(f"rosbag: {path}: its topics table cannot be read ({exc})") from None


class Db3Rows:
    """The messages of one ``.db3`` file in log-time order (see the module docstring).

    Parameters
    ----------
    path : str or Path
        The ``.db3`` file.
    topics : collection of str, optional
        Topics to yield (None = all).
    on_damage : callable
        Receives each damaged place (:class:`~vpp_service.transport.ros2.bag_damage.BagDamage`).

    Attributes
    ----------
    read : int
        Messages yielded so far.
    """

    def __init__(
        self, path: str | Path, topics: Collection[str] | None = None, on_damage: OnDamage = ignore_damage
    ) -> None:
        self.path = Path(path)
        self.topics = topics
        self.on_damage = on_damage
        self.read = 0
        self._cause = "bag.corrupt_row"
        self._damaged = 0

    def _damage(self, where: str) -> None:
        self._damaged += 1
        self.on_damage(BagDamage(self._cause, f"{self.path}: {where} (after {self.read} messages read)"))

    def __iter__(self) -> Iterator[BagMessage]:
        short = _short_by(self.path)
        if short:
            self._cause = "bag.truncated"
        conn = _connect(self.path, bool(short))
        try:
            chosen = {i: (n, t) for i, n, t in _topic_rows(conn, self.path) if self.topics is None or n in self.topics}
            if not chosen:
                return
            for stamp, row, tid in self._keys(conn, list(chosen)):
                try:
                    got = conn.execute("SELECT data FROM messages WHERE id = ?", (row,)).fetchone()
                except apsw.Error as exc:
                    self._damage(f"row {row} (log time {stamp} ns) unreadable: {exc}")
                    continue
                if got is None:
                    continue
                self.read += 1
                topic, ros_type = chosen[tid]
                yield BagMessage(topic, ros_type, int(stamp), bytes(got[0]))
            if short and not self._damaged:  # cut where no row lay
                self._damage(f"the file is {short} bytes shorter than its header says; every row was read")
        finally:
            conn.close()

    def _keys(self, conn: apsw.Connection, topic_ids: list[int]) -> Iterator[tuple[int, int, int]]:
        """(log time, row id, topic id) of the chosen topics' rows, sorted; a broken table gives what it can."""
        where = f"topic_id IN ({','.join('?' * len(topic_ids))})"
        try:  # SQLite sorts the whole table scan before the first row comes back: it fails here or not at all
            cur = conn.execute(
                f"SELECT timestamp, id, topic_id FROM messages NOT INDEXED WHERE {where} ORDER BY timestamp, id",
                topic_ids,
            )
        except apsw.Error:
            yield from sorted(self._scan_keys(conn, where, topic_ids))
            return
        try:
            for t, i, k in cur:
                yield int(t), int(i), int(k)
        except apsw.Error as exc:  # not expected once sorted; counted all the same
            self._damage(f"the sorted keys break off: {exc}")

    def _scan_keys(self, conn: apsw.Connection, where: str, topic_ids: list[int]) -> list[tuple[int, int, int]]:
        """The keys in row-id order up to each break in the table, probing past it (row ids + 1, + 2, + 4, ...)."""
        keys: list[tuple[int, int, int]] = []
        after, step, probes = -1, 0, 0
        while probes <= _PROBES:
            try:
                for t, i, k in conn.execute(
                    f"SELECT timestamp, id, topic_id FROM messages NOT INDEXED WHERE id > ? AND {where} ORDER BY id",
                    [after + step, *topic_ids],
                ):
                    keys.append((int(t), int(i), int(k)))
                    after, step = int(i), 0
                return keys
            except apsw.Error as exc:
                if step == 0:
                    last = f"after row {after}" if after >= 0 else "before its first row"
                    self._damage(f"the messages table breaks off {last}: {exc}")
                step, probes = max(1, 2 * step), probes + 1
        return keys


__all__ = ["Db3Rows", "db3_topics"]
