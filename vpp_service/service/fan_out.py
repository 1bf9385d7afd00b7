"""The pipeline's way out: one queue and thread per sink, and the results' delivery to them.

::

    process stage --deliver--> [queue of sink 1] --> sink 1's thread (sink.write)
                           --> [queue of sink 2] --> sink 2's thread ...

Each sink gets a :class:`~vpp_service.queueing.QueueWorker` sized from its
:meth:`~vpp_service.sinks.base.Sink.queue_spec`, so a slow sink delays only itself. The
sink's own ``block`` (a recording) or the pipeline's ``block`` output policy (a replay)
make the process stage wait for room; otherwise a full queue drops its oldest result
(counted by the sink's queue). A result is *published* once every sink has handled it
and none dropped it; what a stop keeps from a sink's queue is counted ``unsent``
(:class:`~vpp_service.service.ledger.Ledger`). When the last sink thread has exited,
``on_done`` is called.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

from vpp_service.frame import FusionResult
from vpp_service.queueing import Policy, QueueWorker
from vpp_service.service.ledger import Ledger

if TYPE_CHECKING:
    from vpp_service.sinks.base import Sink

log = logging.getLogger(__name__)


class FanOut:
    """Every sink's queue and thread, and the delivery of each result to all of them.

    Parameters
    ----------
    sinks : sequence of Sink
        Opened by the pipeline before :meth:`start`.
    size, policy : int, {"latest", "block"}
        The pipeline's output queue size and policy (a sink's ``queue_spec`` may override them).
    ledger : Ledger
        Where errors, deliveries lost at a stop and published results are counted.
    stopping : threading.Event
        Set by a stop: a blocked delivery gives up (counted ``unsent``).
    on_done : callable
        Called once, when the last sink thread has exited (at once, by :meth:`finish`, without sinks).
    """

    def __init__(
        self,
        sinks: Sequence[Sink],
        *,
        size: int,
        policy: Policy,
        ledger: Ledger,
        stopping: threading.Event,
        on_done: Callable[[], None],
    ) -> None:
        self.sinks = list(sinks)
        self.ledger = ledger
        self._stopping = stopping
        self._on_done = on_done
        self._lock = threading.Lock()
        self._running = len(self.sinks)  # sink threads not yet exited; the last calls on_done
        self.workers: list[QueueWorker[_Delivery]] = [self._worker(sink, size, policy) for sink in self.sinks]

    def _worker(self, sink: Sink, size: int, policy: Policy) -> QueueWorker[_Delivery]:
        """The queue and thread of ``sink``, from its :meth:`~vpp_service.sinks.base.Sink.queue_spec`."""
        spec = sink.queue_spec()
        blocking = "block" in (policy, spec.policy)
        return QueueWorker(
            lambda d: self._write(sink, d),
            size=spec.size or size,
            policy="block" if blocking else "latest",
            name=f"sink-{type(sink).__name__}",
            on_start=sink.start,
            on_exit=lambda: self._finished(sink),
            on_error=lambda d, exc: self._failed(sink, exc),
            on_drop=lambda d: self._delivered(d, dropped=True),
        )

    def queues(self) -> list[tuple[str, QueueWorker[_Delivery]]]:
        """``(sink class name, its queue)`` pairs, for the status and the losses."""
        return [(type(s).__name__, w) for s, w in zip(self.sinks, self.workers, strict=True)]

    def start(self) -> None:
        """Start every sink's thread."""
        for worker in self.workers:
            worker.start()

    def deliver(self, result: FusionResult) -> None:
        """Hand ``result`` to every sink's queue (waiting for room where it blocks)."""
        if not self.workers:
            self.ledger.published(result)
            return
        delivery = _Delivery(result, len(self.workers))
        for worker in self.workers:
            if worker.policy == "block":
                while not worker.put(delivery, timeout=0.1):
                    if self._stopping.is_set() or worker.closed:
                        self._unsendable(delivery)
                        break
            elif not worker.put(delivery):  # a latest queue refuses only once closed: a stop aborted it
                self._unsendable(delivery)

    def finish(self) -> None:
        """No more results: the sink threads write what is queued, then exit (``on_done`` now, without sinks)."""
        for worker in self.workers:
            worker.finish()
        if not self.workers:
            self._on_done()

    def join(self, deadline: float) -> bool:
        """Wait for every sink thread until ``deadline`` (:func:`time.monotonic`); True when all have exited."""
        drained = True
        for worker in self.workers:
            drained = worker.join(max(0.05, deadline - time.monotonic())) and drained
        return drained

    def abort(self) -> None:
        """Discard what is queued (a stop that cannot wait) and give the threads 1 s each to exit."""
        for worker in self.workers:
            worker.abort()
        for worker in self.workers:
            worker.join(1.0)

    def _unsendable(self, delivery: _Delivery) -> None:
        """A sink's queue refused ``delivery`` while stopping: lost there (counted under ``shutdown``)."""
        self.ledger.lost_at_stop("unsent")
        self._delivered(delivery, dropped=True)

    def _write(self, sink: Sink, delivery: _Delivery) -> None:
        """One sink's thread: write one result, then count it delivered there."""
        try:
            sink.write(delivery.result)
        finally:
            self._delivered(delivery)

    def _failed(self, sink: Sink, exc: Exception) -> None:
        """A sink raised on a result: counted (the pipeline's ``errors`` and the sink's), the others go on."""
        self.ledger.count("errors")
        sink.count("errors")
        log.warning("sink %s: %s", type(sink).__name__, exc)

    def _delivered(self, delivery: _Delivery, *, dropped: bool = False) -> None:
        """One sink is done with ``delivery`` (written, failed or dropped); the last one publishes it."""
        with self._lock:
            delivery.remaining -= 1
            delivery.dropped |= dropped
            last = delivery.remaining == 0
        if last and not delivery.dropped:
            self.ledger.published(delivery.result)

    def _finished(self, sink: Sink) -> None:
        """A sink's thread is exiting: its ``finish`` hook, then ``on_done`` once every sink thread has."""
        try:
            sink.finish()
        finally:
            with self._lock:
                self._running -= 1
                last = self._running == 0
            if last:
                self._on_done()


class _Delivery:
    """One result on its way to the sinks: how many sinks still have it queued, whether one dropped it."""

    __slots__ = ("dropped", "remaining", "result")

    def __init__(self, result: FusionResult, remaining: int) -> None:
        self.result = result
        self.remaining = remaining
        self.dropped = False


def close_within(sink: Sink, timeout: float) -> bool:
    """Close ``sink`` on a helper thread; True when it returned without an error within ``timeout`` + 1 s.

    Whatever a sink's library does (a Rerun stream stuck disconnecting from a full disk, a viewer gone),
    the shutdown goes on after the bound; the thread is a daemon and is abandoned.
    """
    failed: list[BaseException] = []

    def close() -> None:
        try:
            sink.close(timeout)
        except Exception as exc:  # noqa: BLE001 - one failing sink must not keep the others open
            failed.append(exc)

    thread = threading.Thread(target=close, name=f"close-{type(sink).__name__}", daemon=True)
    thread.start()
    thread.join(timeout + 1.0)
    if thread.is_alive():
        log.error("sink %s did not close within %.1f s; its output may be incomplete", type(sink).__name__, timeout)
        return False
    if failed:
        log.error("closing sink %s failed: %s", type(sink).__name__, failed[0])
        return False
    return True


__all__ = ["FanOut", "close_within"]
