"""Damage found while reading a rosbag2 bag: what could not be read, why, and where.

The bag readers (:mod:`~vpp_service.transport.ros2.mcap_reader`,
:mod:`~vpp_service.transport.ros2.db3_reader`) play everything readable and report each
damaged place once through an ``on_damage`` callback. The causes, used as counter names:

``bag.truncated``
    The file ends early (a cut copy, a recorder killed): what lies past the end is lost.
``bag.crc``
    An MCAP chunk whose bytes do not match its CRC-32: the whole chunk is skipped.
``bag.corrupt_chunk``
    An MCAP chunk that cannot be decoded (its compression, size or records do not hold).
``bag.corrupt_record``
    MCAP framing broken outside a chunk (an impossible opcode or length): the reader skips
    to the next chunk the file's index names, or stops when there is none. Also a footer
    whose summary offset is not believed (the file is then read without its index).
``bag.corrupt_row``
    An sqlite3 row (or a run of rows) the database refuses in a file of full length.
``bag.unknown_channel``
    An MCAP message on a channel no readable record defines (its definition was damaged).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

#: Every cause a reader reports.
CAUSES = (
    "bag.truncated",
    "bag.crc",
    "bag.corrupt_chunk",
    "bag.corrupt_record",
    "bag.corrupt_row",
    "bag.unknown_channel",
)


class BagDamage(NamedTuple):
    """One damaged place of a bag.

    Attributes
    ----------
    cause : str
        One of :data:`CAUSES`.
    where : str
        The file, byte offset, chunk or row, and the messages read before it, in words.
    """

    cause: str
    where: str

    def __str__(self) -> str:
        return f"{self.cause}: {self.where}"


#: Receives each damaged place as it is found.
OnDamage = Callable[[BagDamage], None]


def ignore_damage(_damage: BagDamage) -> None:
    """An ``on_damage`` that drops the report (the reader still skips the damage)."""


__all__ = ["CAUSES", "BagDamage", "OnDamage", "ignore_damage"]
