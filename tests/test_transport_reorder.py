"""ReorderBuffer: seq order within a bounded window, against plain sorting, with its counters."""

from __future__ import annotations

import random

import pytest

from vpp_service.transport.reorder import ReorderBuffer


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def shuffled(n: int, displacement: int, rng: random.Random) -> list[int]:
    """0..n-1 with each item moved less than ``displacement`` places (sort by seq + noise)."""
    return [s for _, s in sorted((s + rng.uniform(0, displacement - 1e-9), s) for s in range(n))]


def run(buf: ReorderBuffer[str], seqs: list[int]) -> list[int]:
    out = []
    for s in seqs:
        out += [seq for seq, item in buf.push(s, f"item{s}") if item == f"item{seq}"]
    return out + [seq for seq, _ in buf.flush()]


@pytest.mark.parametrize("window", [1, 2, 4, 16])
@pytest.mark.parametrize("seed", range(4))
def test_bounded_shuffles_come_out_sorted(window, seed):
    rng = random.Random(seed)
    seqs = shuffled(300, window, rng)
    buf: ReorderBuffer[str] = ReorderBuffer(window, max_wait_s=3600, clock=Clock())
    assert run(buf, seqs) == sorted(seqs)  # the plain reference: sorting
    st = buf.stats()
    plain_reordered = sum(1 for i, s in enumerate(seqs) if any(p > s for p in seqs[:i]))
    assert st["reordered"] == plain_reordered
    assert st["gaps"] == st["late"] == st["duplicates"] == st["held"] == 0 and st["released"] == 300


@pytest.mark.parametrize("seed", range(6))
def test_missing_seqs_are_counted_as_gaps(seed):
    rng = random.Random(seed)
    kept = [s for s in shuffled(400, 4, rng) if rng.random() > 0.2]
    buf: ReorderBuffer[str] = ReorderBuffer(8, max_wait_s=3600, clock=Clock())
    assert run(buf, kept) == sorted(kept)
    assert buf.stats()["gaps"] == (max(kept) - min(kept) + 1) - len(kept)


@pytest.mark.parametrize("seed", range(4))
def test_duplicates_are_dropped_and_counted(seed):
    rng = random.Random(seed)
    seqs = shuffled(200, 4, rng)
    repeats = rng.sample(range(200), 30)
    stream = list(seqs)
    for s in repeats:  # each repeat shortly after its first copy (a pool's double answer)
        stream.insert(stream.index(s) + rng.randint(1, 3), s)
    buf: ReorderBuffer[str] = ReorderBuffer(8, max_wait_s=3600, clock=Clock())
    assert run(buf, stream) == list(range(200))
    assert buf.stats()["duplicates"] == 30


@pytest.mark.parametrize("window", [1, 3, 8])
def test_never_holds_more_than_the_window(window):
    buf: ReorderBuffer[str] = ReorderBuffer(window, max_wait_s=3600, clock=Clock())
    for s in [0, *range(2, 40)]:  # 1 never comes
        buf.push(s, "x")
        assert buf.stats()["held"] <= window


def test_a_hole_is_waited_for_at_most_max_wait():
    clock = Clock()
    buf: ReorderBuffer[str] = ReorderBuffer(16, max_wait_s=0.5, clock=clock)
    assert buf.push(0, "a") == []  # the first item waits too: an earlier one may come
    clock.t = 0.5
    assert buf.poll() == [(0, "a")]
    assert buf.push(2, "c") == []
    clock.t = 0.9
    assert buf.poll() == []
    clock.t = 1.0
    assert buf.poll() == [(2, "c")]
    assert buf.stats()["gaps"] == 1
    assert buf.push(1, "b") == [(1, "b")]  # late: released out of order, counted
    assert buf.stats()["late"] == 1
    assert buf.push(3, "d") == [(3, "d")]  # in order: at once


def test_the_first_items_are_put_in_order_too():
    clock = Clock()
    buf: ReorderBuffer[str] = ReorderBuffer(4, max_wait_s=1.0, clock=clock)
    assert buf.push(5, "f") == [] and buf.push(3, "d") == [] and buf.push(4, "e") == []
    clock.t = 1.0
    assert [s for s, _ in buf.poll()] == [3, 4, 5]


def test_unexpected_seqs_are_skipped_at_once_without_a_gap():
    mine = {0, 3, 4, 9}
    buf: ReorderBuffer[str] = ReorderBuffer(16, max_wait_s=3600, expected=mine.__contains__, clock=Clock())
    buf.push(0, "a")
    buf.flush()
    assert buf.push(3, "d") == [(3, "d")] and buf.push(4, "e") == [(4, "e")]
    assert buf.push(9, "j") == [(9, "j")]
    assert buf.stats()["gaps"] == 0
    mine.add(12)
    assert buf.push(13, "n") == []  # 12 was expected: waited for
    assert buf.flush() == [(13, "n")] and buf.stats()["gaps"] == 1


def test_a_restarted_stream_resets_the_buffer():
    clock = Clock()
    buf: ReorderBuffer[str] = ReorderBuffer(4, max_wait_s=0.0, clock=clock)
    out = [s for i in range(100, 120) for s, _ in buf.push(i, "x")]
    assert out == list(range(100, 120))
    out = [s for i in range(20) for s, _ in buf.push(i, "y")]
    assert out == list(range(20))  # the first few late, then a reset: nothing lost
    st = buf.stats()
    assert st["resets"] == 1 and st["late"] == 7


@pytest.mark.parametrize(("window", "wait"), [(0, 1.0), (-1, 1.0), (True, 1.0), (4, -0.1), (4, 4000.0)])
def test_bad_parameters_are_refused(window, wait):
    with pytest.raises(ValueError, match=r"window|max_wait_s"):
        ReorderBuffer(window, wait)
