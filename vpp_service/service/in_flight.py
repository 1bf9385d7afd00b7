"""Frames in flight: up to ``n`` frames processed at once, their results handed on in the order they came.

A network on a remote server (:mod:`vpp_service.matchers.triton`) is latency-bound:
the process stage keeps several frames on the servers instead of waiting for each
result. :class:`InFlight` runs ``work(frame)`` on up to ``n`` threads;
:meth:`InFlight.submit` waits while ``n`` frames are in flight (back-pressure:
the pipeline's input queue fills and its policy applies), and one thread hands
each result (or failure) on in submission order, exactly once.

A stop that cannot wait for the servers calls :meth:`InFlight.abandon`: the items
not yet handed on are never handed on (their results are ignored when they come),
and it returns how many there were, for the caller to count as lost.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor, wait
from typing import Generic, TypeVar

T = TypeVar("T")
R = TypeVar("R")


class InFlight(Generic[T, R]):
    """A window of ``n`` items processed concurrently and delivered in order.

    Parameters
    ----------
    n : int
        Items in flight at most (>= 1).
    work : callable
        ``work(item) -> result``, on one of ``n`` threads.
    done : callable
        ``done(result)``, on the delivering thread, in submission order.
    failed : callable
        ``failed(item, exc)`` for an item whose ``work`` (or ``done``) raised, in its place in the order.
    name : str
        Prefix of the thread names.
    """

    def __init__(
        self,
        n: int,
        work: Callable[[T], R],
        done: Callable[[R], None],
        failed: Callable[[T, Exception], None],
        name: str = "in-flight",
    ) -> None:
        if n < 1:
            raise ValueError(f"n must be >= 1, got {n}")
        self.n = n
        self._work, self._done, self._failed = work, done, failed
        self._slots = threading.Semaphore(n)
        self._pool = ThreadPoolExecutor(n, thread_name_prefix=f"{name}-work")
        self._order: queue.SimpleQueue[tuple[T, Future[R]] | None] = queue.SimpleQueue()
        self._thread = threading.Thread(target=self._deliver, name=f"{name}-deliver", daemon=True)
        self._thread.start()
        self._lock = threading.Lock()
        self._outstanding = 0
        self._unclaimed = 0  # submitted, neither handed on (nor being handed on) nor abandoned
        self._abandoned = False
        self.high_water = 0

    @property
    def outstanding(self) -> int:
        """Items submitted and not yet delivered."""
        with self._lock:
            return self._outstanding

    def submit(self, item: T, stop: threading.Event | None = None) -> bool:
        """Start ``item`` once a slot is free (waits while ``n`` are in flight).

        False when ``stop`` was set first, or after :meth:`abandon`: the item was not taken.
        """
        while not self._slots.acquire(timeout=0.1):
            if stop is not None and stop.is_set():
                return False
        with self._lock:
            if self._abandoned:
                self._slots.release()
                return False
            self._outstanding += 1
            self._unclaimed += 1
            self.high_water = max(self.high_water, self._outstanding)
        self._order.put((item, self._pool.submit(self._work, item)))
        return True

    def _deliver(self) -> None:
        while True:
            entry = self._order.get()
            if entry is None:
                return
            item, fut = entry
            while not (fut.done() or self._abandoned):
                wait((fut,), timeout=0.1)  # the result, or an abandon() meanwhile
            with self._lock:
                claimed = not self._abandoned  # else counted by abandon(): never handed on
                if claimed:
                    self._unclaimed -= 1
            try:
                if not claimed:
                    fut.cancel()  # not started yet: never sent
                    continue
                exc = fut.exception()
                if exc is None:
                    self._done(fut.result())
                else:
                    self._failed(item, exc if isinstance(exc, Exception) else RuntimeError(repr(exc)))
            except Exception as err:  # noqa: BLE001 - the delivering thread must survive a failing callback
                self._failed(item, err)
            finally:
                with self._lock:
                    self._outstanding -= 1
                self._slots.release()

    def abandon(self) -> int:
        """Hand nothing more on (a stop that cannot wait); how many items that leaves without a result.

        An item whose result came and is being handed on right now is not among them: it is handed on.
        Later calls return 0, and :meth:`submit` takes no more items.
        """
        with self._lock:
            self._abandoned = True
            n, self._unclaimed = self._unclaimed, 0
        return n

    def close(self, timeout: float | None = None) -> bool:
        """Deliver what is in flight, then end the threads; False when that took longer than ``timeout``."""
        self._order.put(None)
        self._thread.join(timeout)
        self._pool.shutdown(wait=False)
        return not self._thread.is_alive()


__all__ = ["InFlight"]
