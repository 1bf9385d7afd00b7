"""Ordered sinks in a worker pool: files, record and rerun write in seq order, counting gaps, late and duplicates."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.frames import make_frame
from vpp_service.frame import FusionResult
from vpp_service.sinks.base import SinkContext, build_sink
from vpp_service.sinks.ordered import OrderedWrites, check_reorder_options


def result(seq: int) -> FusionResult:
    fr = make_frame(seed=seq).with_(rig="r1", seq=seq)
    return FusionResult(fr, np.full(fr.shape, 1.0 + seq, np.float32))


def pool_context(mine: set[int]) -> SinkContext:
    return SinkContext(rig="r1", extra={"seq_expected": mine.__contains__})


#: A worker's share (0..11 minus the other worker's 2, 5, 8), written out of order, one duplicate; 10 never comes.
MINE = {0, 1, 3, 4, 6, 7, 9, 10, 11}
ARRIVALS = [1, 0, 4, 3, 6, 6, 9, 7, 11]


def test_ordered_writes_reorder_and_count():
    got: list[int] = []
    ow = OrderedWrites(4, 60000, pool_context(MINE), lambda r: got.append(r.frame.seq))
    for s in ARRIVALS:
        ow.write(result(s))
    ow.flush()
    assert got == sorted(set(ARRIVALS))
    st = ow.stats()
    assert st["order_gaps"] == 1 and st["order_duplicates"] == 1 and st["order_late"] == 0
    assert st["order_reordered"] == 3 and st["order_held"] == 0


def test_outside_a_pool_results_go_straight_through():
    got: list[int] = []
    ow = OrderedWrites(16, 500, SinkContext(rig="r1"), lambda r: got.append(r.frame.seq))
    for s in (3, 1, 1, 2):
        ow.write(result(s))
    assert got == [3, 1, 1, 2] and not ow.enabled and ow.stats() == {}


@pytest.mark.parametrize("kind", ["files", "record"])
def test_folder_sinks_write_in_order_and_once(tmp_path, kind):
    sink = build_sink(kind, {"dir": str(tmp_path), "reorder_window": 4}, pool_context(MINE))
    order: list[int] = []
    write_one = sink.write_one
    sink.write_one = lambda r: (order.append(r.frame.seq), write_one(r))  # type: ignore[method-assign]
    sink.open()
    for s in ARRIVALS:
        sink.write(result(s))
    sink.close()
    assert order == sorted(set(ARRIVALS))
    st = sink.stats()
    assert st["written"] == len(set(ARRIVALS)) and st["errors"] == 0  # the duplicate never hit an existing file
    assert st["order_gaps"] == 1 and st["order_duplicates"] == 1
    stems = sorted(p.name.split(".")[0].split("_")[1] for p in tmp_path.iterdir())
    assert [int(s) for s in stems] == sorted(set(ARRIVALS))


def test_a_late_result_is_still_written(tmp_path):
    clock_mine = {0, 1, 2, 3}
    sink = build_sink("files", {"dir": str(tmp_path), "reorder_window": 1}, pool_context(clock_mine))
    sink.open()
    for s in (0, 2, 3, 1):  # window 1: 1 is given up on when 3 comes, then arrives late
        sink.write(result(s))
    sink.close()
    st = sink.stats()
    assert st["written"] == 4 and st["order_late"] == 1 and st["order_gaps"] == 1


def test_rerun_sink_reorders_in_a_pool(tmp_path):
    sink = build_sink(
        "rerun", {"mode": "save", "path": str(tmp_path / "x.rrd"), "max_hz": 0, "queue_size": 64}, pool_context(MINE)
    )
    sink.open()
    for s in ARRIVALS:
        sink.write(result(s))
    sink.close(10.0)
    st = sink.stats()
    assert st["written"] == len(set(ARRIVALS)) and st["order_gaps"] == 1 and st["order_duplicates"] == 1


@pytest.mark.parametrize(("window", "wait"), [(-1, 500), (2000, 500), (True, 500), (4, 0), (4, 1e9), (4, "x")])
def test_bad_reorder_options_are_refused(window, wait):
    with pytest.raises(ValueError, match="reorder_"):
        check_reorder_options(window, wait)


def test_sink_options_name_the_bad_reorder_key(tmp_path):
    with pytest.raises(Exception, match="reorder_window"):
        build_sink("files", {"dir": str(tmp_path), "reorder_window": -3})
