"""vpp_service.queueing: the bounded queue's policies and the worker thread that drains it."""

from __future__ import annotations

import logging
import threading
import time

import pytest

from vpp_service.queueing import BoundedQueue, QueueWorker, ReceiveRings


def reference_queue(items, size):
    """Plain reference of the 'latest' policy: what remains after pushing items into a size-bounded FIFO."""
    q = []
    dropped = 0
    for it in items:
        q.append(it)
        if len(q) > size:
            q.pop(0)
            dropped += 1
    return q, dropped


@pytest.mark.parametrize("size", [1, 3, 5])
def test_bounded_queue_latest_matches_reference(size):
    q = BoundedQueue(size, "latest")
    for i in range(12):
        q.put(i)
        assert len(q) <= size
    ref, dropped = reference_queue(range(12), size)
    assert [q.get(0) for _ in range(len(q))] == ref
    assert q.dropped == dropped and q.high_water == size


def test_bounded_queue_block_waits_for_room():
    q = BoundedQueue(1, "block")
    assert q.put("a")
    assert not q.put("b", timeout=0.05)  # full: times out, nothing lost silently
    threading.Timer(0.05, q.get).start()
    assert q.put("b", timeout=2.0)
    assert q.get(0) == "b" and q.dropped == 0


def test_bounded_queue_close_wakes_getters():
    q = BoundedQueue(2)
    threading.Timer(0.05, q.close).start()
    assert q.get(timeout=2.0) is None
    assert not q.put(1)


@pytest.mark.parametrize(
    ("size", "policy", "message"),
    [(0, "latest", "size must be an integer >= 1"), (2, "newest", "policy must be one of"), (True, "latest", "size")],
)
def test_bounded_queue_bad_args(size, policy, message):
    with pytest.raises(ValueError, match=message):
        BoundedQueue(size, policy)


def test_bounded_queue_discard_counts_separately_from_drops():
    q = BoundedQueue(2, "latest")
    for i in range(3):
        q.put(i)
    assert q.discard() == 2 and len(q) == 0
    assert (q.dropped, q.discarded) == (1, 2)


class Recorder:
    """A handle that records items, optionally slowly, failing on the items listed in ``fail``."""

    def __init__(self, delay: float = 0.0, fail: tuple = ()) -> None:
        self.items: list = []
        self.delay, self.fail = delay, fail
        self.release = threading.Event()
        self.release.set()

    def __call__(self, item) -> None:
        self.release.wait()
        if self.delay:
            time.sleep(self.delay)
        if item in self.fail:
            raise RuntimeError(f"bad item {item}")
        self.items.append(item)


def test_worker_handles_every_item_in_order_with_block():
    rec = Recorder(delay=0.002)
    w = QueueWorker(rec, size=2, policy="block", name="t-block")
    w.start()
    for i in range(30):
        assert w.put(i, timeout=5.0)
    assert w.close(5.0)
    assert rec.items == list(range(30))
    assert (w.handled, w.dropped, w.discarded, w.errors) == (30, 0, 0, 0) and w.high_water <= 2


def test_worker_latest_drops_the_oldest_and_the_newest_survives():
    rec = Recorder()
    rec.release.clear()  # the thread is stuck on item 0
    w = QueueWorker(rec, size=3, policy="latest", name="t-latest")
    w.start()
    assert w.put(0)
    deadline = time.monotonic() + 5
    while len(w) and time.monotonic() < deadline:  # wait until the thread took item 0
        time.sleep(0.005)
    for i in range(1, 11):
        assert w.put(i)  # never blocks
    assert len(w) == 3 and w.dropped == 7
    rec.release.set()
    assert w.close(5.0)
    assert rec.items == [0, 8, 9, 10] and w.handled == 4


def test_items_put_before_start_wait_in_the_queue():
    rec = Recorder()
    w = QueueWorker(rec, size=2, policy="latest")
    for i in range(5):
        w.put(i)
    assert w.dropped == 3 and rec.items == []
    w.start()
    assert w.close(5.0) and rec.items == [3, 4]


def test_close_while_a_producer_is_blocked_wakes_it():
    rec = Recorder()
    rec.release.clear()
    w = QueueWorker(rec, size=1, policy="block", name="t-blocked")
    w.start()
    w.put("a")
    deadline = time.monotonic() + 5
    while len(w) and time.monotonic() < deadline:
        time.sleep(0.005)
    w.put("b")  # fills the queue
    got: list[bool] = []
    producer = threading.Thread(target=lambda: got.append(w.put("c")))  # blocks: no room
    producer.start()
    time.sleep(0.05)
    assert producer.is_alive()
    t0 = time.monotonic()
    assert not w.close(0.2)  # the handle is stuck: close gives up after its timeout
    assert time.monotonic() - t0 < 1.0
    producer.join(2.0)
    assert got == [False] and not producer.is_alive()
    assert w.discarded == 1 and w.closed  # "b" never handled
    rec.release.set()
    assert w.join(2.0) and rec.items == ["a"]  # the abandoned thread exits after its item


def test_close_with_timeout_abandons_a_stuck_thread_and_counts_the_queue(caplog):
    rec = Recorder()
    rec.release.clear()
    w = QueueWorker(rec, size=4, policy="latest", name="t-stuck")
    w.start()
    for i in range(4):
        w.put(i)
    with caplog.at_level(logging.WARNING, logger="vpp_service.queueing"):
        t0 = time.monotonic()
        assert w.close(0.3) is False
        assert 0.25 <= time.monotonic() - t0 < 1.5
    assert "t-stuck" in caplog.text and "abandoning" in caplog.text
    assert w.discarded == 3 and not w.put(9)
    rec.release.set()
    assert w.join(2.0) and rec.items == [0]


def test_exception_in_handle_is_logged_counted_and_not_fatal(caplog):
    rec = Recorder(fail=(1, 3))
    w = QueueWorker(rec, size=8, policy="block", name="t-errors")
    w.start()
    with caplog.at_level(logging.WARNING, logger="vpp_service.queueing"):
        for i in range(5):
            w.put(i)
        assert w.close(5.0)
    assert rec.items == [0, 2, 4] and (w.handled, w.errors) == (3, 2)
    assert caplog.text.count("t-errors: handling an item failed") == 2 and "bad item 3" in caplog.text


def test_on_error_gets_the_item_and_hooks_run_on_the_thread():
    seen: list = []
    threads: set[str] = set()
    w = QueueWorker(
        lambda i: 1 / i,
        size=4,
        policy="block",
        name="t-hooks",
        on_start=lambda: threads.add(threading.current_thread().name),
        on_exit=lambda: seen.append("exit"),
        on_error=lambda item, exc: seen.append((item, type(exc).__name__)),
    )
    w.start()
    for i in (1, 0, 2):
        w.put(i)
    assert w.close(5.0)
    assert seen == [(0, "ZeroDivisionError"), "exit"] and threads == {"t-hooks"}
    assert (w.handled, w.errors) == (2, 1)


def test_failing_hooks_are_counted_and_the_worker_still_runs(caplog):
    rec = Recorder()

    def boom() -> None:
        raise OSError("no viewer")

    w = QueueWorker(rec, size=2, policy="block", name="t-hookfail", on_start=boom, on_exit=boom)
    w.start()
    w.put(1)
    with caplog.at_level(logging.WARNING, logger="vpp_service.queueing"):
        assert w.close(5.0)
    assert rec.items == [1] and w.errors == 2 and "on_exit failed" in caplog.text


def test_abort_from_handle_stops_after_the_current_item():
    w: QueueWorker[int]
    rec: list[int] = []

    def handle(i: int) -> None:
        rec.append(i)
        if i == 2:
            w.abort()

    w = QueueWorker(handle, size=10, policy="block")
    for i in range(6):
        w.put(i)
    w.start()
    assert w.join(5.0)
    assert rec == [0, 1, 2] and w.discarded == 3 and not w.put(7)


def test_start_twice_and_bad_arguments():
    w = QueueWorker(lambda i: None, size=1)
    w.start()
    with pytest.raises(RuntimeError, match="already started"):
        w.start()
    assert w.close(1.0)
    with pytest.raises(TypeError, match="handle must be callable"):
        QueueWorker("not callable", size=1)
    with pytest.raises(ValueError, match="size must be an integer >= 1"):
        QueueWorker(lambda i: None, size=0)
    with pytest.raises(ValueError, match="policy must be one of"):
        QueueWorker(lambda i: None, size=1, policy="newest")


def test_close_without_start_discards_at_once():
    w = QueueWorker(lambda i: None, size=2)
    assert QueueWorker(lambda i: None, size=2).close(5.0)  # nothing queued: nothing lost
    w.put(1)
    t0 = time.monotonic()
    assert w.close(5.0) is False and time.monotonic() - t0 < 0.5
    assert w.closed and w.discarded == 1 and len(w) == 0


# ------------------------------------------------------------ ReceiveRings
def test_receive_rings_latest_drops_the_oldest_per_topic_and_counts():
    rings: ReceiveRings[int] = ReceiveRings({"a": 2, "b": 1}, "latest")
    for i in range(5):
        rings.put("a", i)
    rings.put("b", 10)
    rings.put("b", 11)
    assert rings.dropped == {"a": 3, "b": 1} and rings.dropped_total == 4 and len(rings) == 3
    assert [rings.take("a"), rings.take("a"), rings.take("a")] == [3, 4, None]
    assert rings.take("b") == 11 and rings.keys == ["a", "b"]


def test_receive_rings_block_waits_for_room_and_loses_nothing():
    rings: ReceiveRings[int] = ReceiveRings({"a": 1}, "block")
    rings.put("a", 0)
    done = threading.Event()
    threading.Thread(target=lambda: (rings.put("a", 1), done.set()), daemon=True).start()
    assert not done.wait(0.2)  # the producer waits: the ring is full
    assert rings.take("a") == 0
    assert done.wait(2.0) and rings.take("a") == 1 and rings.dropped_total == 0


def test_receive_rings_close_releases_a_blocked_producer_and_counts_its_drop():
    rings: ReceiveRings[int] = ReceiveRings({"a": 1}, "block")
    rings.put("a", 0)
    done = threading.Event()
    threading.Thread(target=lambda: (rings.put("a", 1), done.set()), daemon=True).start()
    assert not done.wait(0.1)
    rings.close()
    assert done.wait(2.0) and rings.dropped == {"a": 1} and rings.take("a") == 1
    assert rings.wait(0.01) is False  # closed and empty: no wait


def test_receive_rings_wait_wakes_on_a_message():
    rings: ReceiveRings[int] = ReceiveRings({"a": 4})
    threading.Timer(0.1, rings.put, ("a", 7)).start()
    t0 = time.monotonic()
    assert rings.wait(5.0) and time.monotonic() - t0 < 2.0


@pytest.mark.parametrize(
    ("sizes", "policy", "match"),
    [({}, "latest", "at least one"), ({"a": 0}, "latest", "sizes"), ({"a": 1}, "newest", "policy")],
)
def test_receive_rings_bad_arguments(sizes, policy, match):
    with pytest.raises(ValueError, match=match):
        ReceiveRings(sizes, policy)
