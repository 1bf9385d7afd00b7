"""InFlight: results in submission order whatever order the work finishes in, back-pressure, failures in place."""

from __future__ import annotations

import threading
import time

import pytest

from vpp_service.service.in_flight import InFlight


def test_results_leave_in_order_though_work_finishes_out_of_order():
    done: list[int] = []
    # later items finish first: item i sleeps (10 - i) * 10 ms
    window: InFlight[int, int] = InFlight(
        4, lambda i: (time.sleep((10 - i) * 0.01), i)[1], done.append, lambda i, e: done.append(-1)
    )
    for i in range(10):
        window.submit(i)
    assert window.close(10)
    assert done == list(range(10))
    assert window.high_water == 4 and window.outstanding == 0


def test_submit_waits_while_the_window_is_full():
    release = threading.Event()
    window: InFlight[int, int] = InFlight(2, lambda i: (release.wait(10), i)[1], lambda r: None, lambda i, e: None)
    assert window.submit(0) and window.submit(1)
    stop = threading.Event()
    blocked = threading.Thread(target=lambda: window.submit(2, stop))
    blocked.start()
    time.sleep(0.3)
    assert blocked.is_alive() and window.outstanding == 2  # the third waits for a slot
    release.set()
    blocked.join(5)
    assert not blocked.is_alive()
    assert window.close(10)


def test_a_stop_ends_a_waiting_submit():
    release = threading.Event()
    window: InFlight[int, int] = InFlight(1, lambda i: (release.wait(10), i)[1], lambda r: None, lambda i, e: None)
    window.submit(0)
    stop = threading.Event()
    stop.set()
    assert window.submit(1, stop) is False
    release.set()
    assert window.close(10)


def test_a_failure_is_reported_in_its_place_exactly_once():
    events: list[tuple[str, int]] = []

    def work(i: int) -> int:
        if i == 2:
            raise ValueError("bad frame")
        time.sleep(0.01 * (5 - i))
        return i

    window: InFlight[int, int] = InFlight(
        3, work, lambda r: events.append(("done", r)), lambda i, e: events.append(("failed", i))
    )
    for i in range(5):
        window.submit(i)
    assert window.close(10)
    assert events == [("done", 0), ("done", 1), ("failed", 2), ("done", 3), ("done", 4)]


def test_window_size_must_be_positive():
    with pytest.raises(ValueError, match="n must be >= 1"):
        InFlight(0, lambda i: i, lambda r: None, lambda i, e: None)


def test_abandon_counts_what_was_not_handed_on_and_never_hands_it_on():
    """A stop that cannot wait: the items still out are counted once, their late answers ignored."""
    release = threading.Event()
    done: list[int] = []
    failed: list[int] = []
    window: InFlight[int, int] = InFlight(
        3, lambda i: i if i == 0 else (release.wait(10), i)[1], done.append, lambda i, e: failed.append(i)
    )
    for i in range(3):
        assert window.submit(i)
    deadline = time.monotonic() + 5
    while not done and time.monotonic() < deadline:
        time.sleep(0.01)
    assert done == [0] and window.outstanding == 2
    assert window.abandon() == 2  # 1 and 2 are still out
    assert window.abandon() == 0  # counted once
    assert window.submit(3) is False  # takes nothing more
    release.set()  # the late answers come
    assert window.close(10)
    assert done == [0] and failed == [] and window.outstanding == 0
