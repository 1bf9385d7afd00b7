"""Separate-topics synchronizer: exact (seq) and approximate (stamp) matching, drops, bounds."""

from __future__ import annotations

import pytest

from vpp_service.transport.sync import Synchronizer

MS = 1_000_000


def reference_exact(streams):
    """Plain reference: a seq is matched iff every topic has it."""
    sets = [{s for s, _ in v} for v in streams.values()]
    return sorted(set.intersection(*sets))


@pytest.mark.parametrize("order", ["lrd", "dlr", "rdl"])
def test_exact_matches_by_seq_in_any_arrival_order(order):
    sync = Synchronizer(("l", "r", "d"), "exact", queue_size=5)
    names = {"l": "l", "r": "r", "d": "d"}
    out = []
    for seq in range(4):
        for t in order:
            got = sync.add(names[t], seq, seq * 33 * MS, f"{t}{seq}")
            if got is not None:
                out.append(got)
    assert [o["l"] for o in out] == ["l0", "l1", "l2", "l3"]
    assert all(o["d"][1:] == o["l"][1:] == o["r"][1:] for o in out)
    assert sync.matched == 4 and sync.dropped == 0


def test_exact_drops_unmatched_and_compares_to_reference():
    sync = Synchronizer(("left", "right"), "exact", queue_size=3)
    streams = {"left": [(s, s) for s in range(10)], "right": [(s, s) for s in range(10) if s % 3]}
    matched = []
    for s in range(10):
        for t in ("left", "right"):
            if (s, s) in streams[t]:
                got = sync.add(t, s, s, s)
                if got:
                    matched.append(got["left"])
    assert matched == reference_exact(streams)
    # left 0, 3, 6, 9 never get a partner; 0, 3, 6 are dropped when a newer set matches
    assert sync.dropped == 3
    assert sync.pending() == {"left": 1, "right": 0}


def test_queue_is_bounded():
    sync = Synchronizer(("a", "b"), "exact", queue_size=2)
    for s in range(10):
        assert sync.add("a", s, 0, s) is None
        assert sync.pending()["a"] <= 2
    assert sync.dropped == 8
    assert sync.add("b", 9, 0, 9) == {"a": 9, "b": 9}


def test_approximate_within_threshold():
    sync = Synchronizer(("l", "r"), "approximate", queue_size=5, threshold_ns=5 * MS)
    assert sync.add("l", 0, 100 * MS, "l0") is None
    assert sync.add("r", 0, 103 * MS, "r0") == {"l": "l0", "r": "r0"}
    # too far apart: no set, then the stale one is dropped when a later set matches
    assert sync.add("l", 1, 200 * MS, "l1") is None
    assert sync.add("r", 1, 210 * MS, "r1") is None
    assert sync.add("l", 2, 212 * MS, "l2") == {"l": "l2", "r": "r1"}
    assert sync.dropped == 1  # l1
    assert sync.matched == 2


def test_approximate_picks_closest_candidate():
    sync = Synchronizer(("l", "r"), "approximate", queue_size=5, threshold_ns=10 * MS)
    sync.add("r", 0, 95 * MS, "r_early")
    sync.add("r", 1, 99 * MS, "r_close")
    got = sync.add("l", 7, 100 * MS, "l")
    assert got == {"l": "l", "r": "r_close"}
    assert sync.dropped == 1


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"topics": ("a",)}, "topics"),
        ({"topics": ("a", "a")}, "topics"),
        ({"mode": "fuzzy"}, "mode"),
        ({"queue_size": 0}, "queue_size"),
        ({"threshold_ns": -1}, "threshold_ns"),
    ],
)
def test_bad_arguments(kwargs, match):
    args = {"topics": ("a", "b"), **kwargs}
    with pytest.raises(ValueError, match=match):
        Synchronizer(**args)


def test_unknown_topic():
    with pytest.raises(ValueError, match="topic"):
        Synchronizer(("a", "b")).add("c", 0, 0, None)


def _same_size(parts):
    """Consistency check of the tests: every part's value is (name, size) and the sizes agree."""
    return len({size for _, size in parts.values()}) == 1


@pytest.mark.parametrize("forged_first", [True, False])
def test_inconsistent_part_cannot_destroy_a_consistent_set(forged_first):
    """A forged part carrying a victim's seq (wrong size) is passed over; the genuine set still matches."""
    sync = Synchronizer(("l", "r", "d"), "exact", queue_size=5, consistent=_same_size)
    forged = ("forged", 1)
    out = []
    if forged_first:
        assert sync.add("d", 3, 0, forged) is None
    for t in ("l", "r"):
        assert sync.add(t, 3, 0, (t, 64)) is None
    if not forged_first:
        assert sync.add("d", 3, 0, forged) is None  # completes an inconsistent set: not emitted, nothing consumed
    got = sync.add("d", 3, 0, ("d", 64))
    out.append(got)
    assert out == [{"l": ("l", 64), "r": ("r", 64), "d": ("d", 64)}]
    assert sync.matched == 1 and sync.inconsistent == 1 and sync.dropped == 0
    assert sync.pending() == {"l": 0, "r": 0, "d": 0}


def test_approximate_skips_an_inconsistent_closest_candidate():
    sync = Synchronizer(("l", "r"), "approximate", queue_size=5, threshold_ns=10 * MS, consistent=_same_size)
    sync.add("r", 0, 99 * MS, ("forged", 1))
    sync.add("r", 1, 97 * MS, ("r", 64))
    assert sync.add("l", 7, 100 * MS, ("l", 64)) == {"l": ("l", 64), "r": ("r", 64)}


def test_candidate_combinations_are_bounded():
    """A flood of same-seq forgeries costs at most max_candidates checks per offered message."""
    calls = []

    def never(parts):
        calls.append(1)
        return False

    sync = Synchronizer(("a", "b"), "exact", queue_size=50, consistent=never, max_candidates=8)
    for _ in range(40):
        sync.add("a", 1, 0, "x")
    calls.clear()
    assert sync.add("b", 1, 0, "y") is None
    assert len(calls) == 8
    with pytest.raises(ValueError, match="max_candidates"):
        Synchronizer(("a", "b"), max_candidates=0)
