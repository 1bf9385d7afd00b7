"""Damaged .db3 bags: every readable row is played, bit for bit; each damaged place is reported by cause.

The bag is written with rosbags (helpers/damaged_bags.write_test_bag: 20 stamps of the five stereo topics, 128 x
160 RGB images; about 2.5 MB of 4 KiB pages, each image's 61 KB on a chain of overflow pages). SQLite
stores the rows in insertion order, so a file cut at a fraction f of its bytes holds about f of the rows
whole: at least f * 100 - 3 (the rows whose overflow chains run past the cut, and the one astride it, are
lost). 4 KiB of garbage always covers the start of one page (a page's header or an overflow page's
next-page pointer), so SQLite refuses the row or rows of that page and reads the others.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from helpers.damaged_bags import cut, garble, write_test_bag
from vpp_service.transport.ros2.bag import bag_topics, read_bag


@pytest.fixture(scope="module")
def intact(tmp_path_factory) -> Path:
    return write_test_bag(tmp_path_factory.mktemp("db3") / "bag", "sqlite3")


def read(path: Path) -> tuple[list, list]:
    damage: list = []
    return list(read_bag(path, on_damage=damage.append)), damage


def in_order_within(got: list, ref: list) -> bool:
    """``got`` is ``ref`` with some messages left out (same bytes, same order)."""
    it = iter(ref)
    return all(any(m == r for r in it) for m in got)


@pytest.mark.parametrize("fraction", [0.5, 0.9, 0.99])
def test_a_cut_file_plays_every_whole_row(intact, tmp_path, fraction):
    ref, none = read(intact)
    assert len(ref) == 100 and not none
    damaged = cut(intact, tmp_path / "cut.db3", fraction)
    got, damage = read(damaged)
    assert in_order_within(got, ref) and len(got) >= int(fraction * 100) - 3
    assert damage and {d.cause for d in damage} == {"bag.truncated"}
    assert all(str(damaged) in d.where and (" row " in d.where) for d in damage)
    assert bag_topics(damaged) == bag_topics(intact)


def test_a_file_cut_at_a_page_boundary_reads_no_zero_filled_page(intact, tmp_path):
    """A cut inside a page or at its edge: only genuine bytes come back (never a page's missing part as zeros)."""
    ref, _ = read(intact)
    for at in (intact.stat().st_size * 9 // 10, intact.stat().st_size * 9 // 10 // 4096 * 4096):
        damaged = tmp_path / f"cut{at}.db3"
        damaged.write_bytes(intact.read_bytes()[:at])
        got, _ = read(damaged)
        assert in_order_within(got, ref)


def test_garbage_costs_only_the_rows_it_touches(intact, tmp_path):
    ref, _ = read(intact)
    got, damage = read(garble(intact, tmp_path / "garbled.db3"))
    assert in_order_within(got, ref) and 97 <= len(got) < 100
    assert damage and {d.cause for d in damage} == {"bag.corrupt_row"}
    assert all("row " in d.where and "log time" in d.where for d in damage)


def test_nothing_readable_is_an_error_naming_the_file_and_the_cause(intact, tmp_path):
    stub = cut(intact, tmp_path / "stub.db3", 4096 / intact.stat().st_size)  # page 1 only: the schema
    with pytest.raises(ValueError, match="topics table cannot be read") as err:
        list(read_bag(stub))
    assert str(stub) in str(err.value)
    (tmp_path / "junk.db3").write_bytes(b"\0" * 4096)
    with pytest.raises(ValueError, match="not an sqlite3 database"):
        list(read_bag(tmp_path / "junk.db3"))


def test_an_intact_bag_reads_as_rosbags_reads_it(intact):
    from rosbags.rosbag2 import Reader

    with Reader(intact.parent) as reader:
        want = [(c.topic, c.msgtype, ts, bytes(raw)) for c, ts, raw in reader.messages()]
    got, damage = read(intact)
    assert [(m.topic, m.ros_type, m.log_time_ns, m.data) for m in got] == want and not damage
