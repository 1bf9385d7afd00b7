"""A bounded queue and the one thread that drains it, and a network source's receive rings.

The pipeline (source -> process -> sinks) and every sink that must not block
the pipeline (Zenoh publishing, Rerun logging) decouple a producer from a slower
consumer the same way: a :class:`QueueWorker` owns a :class:`BoundedQueue` and a
daemon thread that calls ``handle(item)`` for each queued item, in order.

Full-queue policies (:data:`POLICIES`)::

    latest   put on a full queue drops the OLDEST item (counted in ``dropped``):
             a live stream, the freshest item wins and the producer never waits
    block    put waits for room (optionally with a timeout): lossless replay,
             the producer slows down instead

Ending a worker::

    finish()        no new items; the thread handles what is queued, then exits
    abort()         no new items; what is queued is discarded (counted in
                    ``discarded``); the thread exits after its current item
    close(timeout)  finish(), wait up to ``timeout`` s, then abort() and leave a
                    thread stuck in ``handle`` behind (a daemon) rather than hang

An exception from ``handle`` is counted in ``errors`` and handed to ``on_error``
(or logged); it never stops the worker.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Generic, Literal, TypeVar

log = logging.getLogger(__name__)

T = TypeVar("T")

#: What ``put`` does on a full queue.
Policy = Literal["latest", "block"]
#: The accepted policies (see the module docstring).
POLICIES: tuple[Policy, ...] = ("latest", "block")


class BoundedQueue(Generic[T]):
    """A thread-safe FIFO of at most ``size`` items with a full-queue policy.

    Parameters
    ----------
    size : int
        Capacity (>= 1).
    policy : {"latest", "block"}
        ``latest``: ``put`` on a full queue drops the oldest item (counted in
        :attr:`dropped`); ``block``: ``put`` waits for room.
    on_drop : callable or None
        ``on_drop(item)`` for each item that leaves the queue unhandled (dropped by
        ``latest`` or removed by :meth:`discard`), called outside the queue's lock.

    Attributes
    ----------
    dropped : int
        Items dropped by the ``latest`` policy.
    discarded : int
        Items removed unhandled by :meth:`discard`.
    high_water : int
        Largest length seen.
    """

    def __init__(self, size: int, policy: Policy = "latest", on_drop: Callable[[T], None] | None = None) -> None:
        if isinstance(size, bool) or not isinstance(size, int) or size < 1:
            raise ValueError(f"size must be an integer >= 1, got {size!r}")
        if policy not in POLICIES:
            raise ValueError(f"policy must be one of {', '.join(POLICIES)}, got {policy!r}")
        self.size = size
        self.policy: Policy = policy
        self._on_drop = on_drop
        self._items: deque[T] = deque()
        self._cond = threading.Condition()
        self._closed = False
        self.dropped = 0
        self.discarded = 0
        self.high_water = 0

    def put(self, item: T, timeout: float | None = None) -> bool:
        """Add ``item``; False when it could not be queued (closed, or ``block`` timed out).

        Parameters
        ----------
        item : T
            The item.
        timeout : float or None
            ``block`` only: longest wait for room in seconds (None = until room or close).
        """
        dropped: list[T] = []
        with self._cond:
            if self.policy == "block":
                ok = self._cond.wait_for(lambda: self._closed or len(self._items) < self.size, timeout)
                if not ok or self._closed:
                    return False
            elif self._closed:
                return False
            elif len(self._items) >= self.size:
                dropped.append(self._items.popleft())
                self.dropped += 1
            self._items.append(item)
            self.high_water = max(self.high_water, len(self._items))
            self._cond.notify_all()
        self._dropped(dropped)
        return True

    def _dropped(self, items: list[T]) -> None:
        """Tell ``on_drop`` of items that left the queue unhandled (outside the lock)."""
        if self._on_drop is not None:
            for item in items:
                self._on_drop(item)

    def get(self, timeout: float | None = None) -> T | None:
        """Remove and return the oldest item; None on timeout or when closed and empty."""
        with self._cond:
            if not self._cond.wait_for(lambda: self._items or self._closed, timeout):
                return None
            if not self._items:
                return None
            item = self._items.popleft()
            self._cond.notify_all()
            return item

    def close(self) -> None:
        """Refuse new items and wake every waiter (queued items can still be taken)."""
        with self._cond:
            self._closed = True
            self._cond.notify_all()

    def discard(self) -> int:
        """Remove every queued item unhandled (counted in :attr:`discarded`); returns how many."""
        with self._cond:
            items = list(self._items)
            self._items.clear()
            self.discarded += len(items)
            self._cond.notify_all()
        self._dropped(items)
        return len(items)

    @property
    def closed(self) -> bool:
        """True once :meth:`close` was called."""
        return self._closed

    def __len__(self) -> int:
        with self._cond:
            return len(self._items)


class QueueWorker(Generic[T]):
    """A :class:`BoundedQueue` drained by its own daemon thread calling ``handle(item)``.

    Parameters
    ----------
    handle : callable
        ``handle(item)``, called on the worker thread for each item, in order.
    size : int
        Queue capacity (>= 1).
    policy : {"latest", "block"}
        Full-queue policy (see the module docstring).
    name : str
        Thread name (also used in log lines).
    on_start : callable or None
        Called once on the worker thread before the first item (e.g. connect).
    on_exit : callable or None
        Called once on the worker thread after the last item, also after
        :meth:`abort` (e.g. flush, or finish the next stage).
    on_error : callable or None
        ``on_error(item, exc)`` for an exception from ``handle``; None = log it.
    on_drop : callable or None
        ``on_drop(item)`` for each item dropped or discarded unhandled (see :class:`BoundedQueue`).

    Attributes
    ----------
    queue : BoundedQueue
        The queue (its ``dropped``, ``discarded`` and ``high_water`` counters).
    handled : int
        Items ``handle`` returned from normally.
    errors : int
        Exceptions from ``handle``, ``on_start``, ``on_exit`` or ``on_error``.

    Notes
    -----
    Items may be put before :meth:`start`; they wait in the queue.
    """

    def __init__(
        self,
        handle: Callable[[T], None],
        *,
        size: int,
        policy: Policy = "latest",
        name: str = "worker",
        on_start: Callable[[], None] | None = None,
        on_exit: Callable[[], None] | None = None,
        on_error: Callable[[T, Exception], None] | None = None,
        on_drop: Callable[[T], None] | None = None,
    ) -> None:
        if not callable(handle):
            raise TypeError("handle must be callable")
        self.queue: BoundedQueue[T] = BoundedQueue(size, policy, on_drop)
        self.name = name
        self._handle = handle
        self._on_start, self._on_exit, self._on_error = on_start, on_exit, on_error
        self._abort = threading.Event()
        self._thread: threading.Thread | None = None
        self.handled = 0
        self.errors = 0

    # ------------------------------------------------------------ queue view
    @property
    def size(self) -> int:
        """Queue capacity."""
        return self.queue.size

    @property
    def policy(self) -> Policy:
        """Full-queue policy."""
        return self.queue.policy

    @property
    def dropped(self) -> int:
        """Items dropped by the ``latest`` policy."""
        return self.queue.dropped

    @property
    def discarded(self) -> int:
        """Items left unhandled by :meth:`abort` (or a timed-out :meth:`close`)."""
        return self.queue.discarded

    @property
    def high_water(self) -> int:
        """Largest queue length seen."""
        return self.queue.high_water

    @property
    def closed(self) -> bool:
        """True once no new items are accepted (:meth:`finish`, :meth:`abort` or :meth:`close`)."""
        return self.queue.closed

    @property
    def started(self) -> bool:
        """True once :meth:`start` was called."""
        return self._thread is not None

    def __len__(self) -> int:
        return len(self.queue)

    # -------------------------------------------------------------- control
    def put(self, item: T, timeout: float | None = None) -> bool:
        """Queue ``item`` under the policy; False when refused (closed, or ``block`` timed out)."""
        return self.queue.put(item, timeout)

    def start(self) -> None:
        """Start the worker thread.

        Raises
        ------
        RuntimeError
            When already started (a worker runs once).
        """
        if self._thread is not None:
            raise RuntimeError(f"{self.name}: already started")
        self._thread = threading.Thread(target=self._run, name=self.name, daemon=True)
        self._thread.start()

    def finish(self) -> None:
        """Accept no new items; the thread handles what is queued, then exits."""
        self.queue.close()

    def abort(self) -> int:
        """Accept no new items and discard the queued ones; returns how many were discarded.

        The thread exits after the item it is handling (safe to call from ``handle``).
        """
        self._abort.set()
        self.queue.close()
        return self.queue.discard()

    def join(self, timeout: float | None = None) -> bool:
        """Wait up to ``timeout`` s for the thread to exit; True when it has (or never started)."""
        t = self._thread
        if t is None or t is threading.current_thread():
            return True
        t.join(timeout)
        return not t.is_alive()

    def close(self, timeout: float = 5.0) -> bool:
        """Finish, wait up to ``timeout`` s, then abort; True when everything queued was handled.

        A thread still inside ``handle`` at the deadline is left behind (it is a
        daemon) and exits after that item; the items still queued are discarded.
        A worker that was never started discards what is queued at once.
        """
        if self._thread is None:
            return self.abort() == 0
        deadline = time.monotonic() + max(0.0, float(timeout))
        self.finish()
        if self.join(max(0.0, deadline - time.monotonic())):
            return True
        n = self.abort()
        log.warning(
            "%s: not finished within %.1f s; abandoning the thread (%d queued items discarded)", self.name, timeout, n
        )
        return False

    # --------------------------------------------------------------- thread
    def _call(self, what: str, fn: Callable[..., None] | None, *args: object) -> None:
        if fn is None:
            return
        try:
            fn(*args)
        except Exception as exc:  # noqa: BLE001 - a hook must not kill the worker
            self.errors += 1
            log.warning("%s: %s failed: %r", self.name, what, exc)

    def _run(self) -> None:
        self._call("on_start", self._on_start)
        while not self._abort.is_set():
            item = self.queue.get()
            if item is None:  # closed and empty
                break
            try:
                self._handle(item)
                self.handled += 1
            except Exception as exc:  # noqa: BLE001 - one bad item must not stop the worker
                self.errors += 1
                if self._on_error is None:
                    log.warning("%s: handling an item failed: %r", self.name, exc)
                else:
                    self._call("on_error", self._on_error, item, exc)
        self._call("on_exit", self._on_exit)


class ReceiveRings(Generic[T]):
    """The receive rings of a network source: one bounded ring per topic, one policy, one count of drops.

    The network's callback threads :meth:`put` (each message into its topic's
    ring); the source's own thread :meth:`take` s them and :meth:`wait` s for more.
    The pipeline's input policy applies here, in one place, for every network
    source (Zenoh, ROS 2)::

        latest   a full ring drops its OLDEST message, counted per topic in dropped
        block    put waits for room (back-pressure through the network link);
                 once the rings are closed (the source stops) it drops and counts instead

    Parameters
    ----------
    sizes : mapping of str to int
        Capacity (>= 1) of each topic's ring.
    policy : {"latest", "block"}
        Full-ring policy.

    Attributes
    ----------
    dropped : dict of str to int
        Messages dropped from each topic's ring.
    """

    def __init__(self, sizes: dict[str, int], policy: Policy = "latest") -> None:
        if not sizes:
            raise ValueError("sizes: at least one topic")
        for key, n in sizes.items():
            if isinstance(n, bool) or not isinstance(n, int) or n < 1:
                raise ValueError(f"sizes[{key!r}] must be an integer >= 1, got {n!r}")
        if policy not in POLICIES:
            raise ValueError(f"policy must be one of {', '.join(POLICIES)}, got {policy!r}")
        self.sizes = dict(sizes)
        self.policy: Policy = policy
        self._rings: dict[str, deque[T]] = {k: deque() for k in sizes}
        self._cond = threading.Condition()
        self._closed = False
        self.dropped: dict[str, int] = dict.fromkeys(sizes, 0)

    @property
    def keys(self) -> list[str]:
        """The topics, in the order they were given."""
        return list(self._rings)

    @property
    def dropped_total(self) -> int:
        """Messages dropped from every ring."""
        with self._cond:
            return sum(self.dropped.values())

    def put(self, key: str, item: T) -> None:
        """Queue ``item`` in ``key``'s ring under the policy (blocks under ``block`` while the ring is full).

        Raises
        ------
        KeyError
            Unknown topic.
        """
        ring, size = self._rings[key], self.sizes[key]
        with self._cond:
            if self.policy == "block":
                self._cond.wait_for(lambda: self._closed or len(ring) < size)
            if len(ring) >= size:  # latest, or closed while waiting: the oldest goes
                ring.popleft()
                self.dropped[key] += 1
            ring.append(item)
            self._cond.notify_all()

    def take(self, key: str) -> T | None:
        """The oldest message of ``key``'s ring, None when it is empty."""
        with self._cond:
            ring = self._rings[key]
            if not ring:
                return None
            item = ring.popleft()
            self._cond.notify_all()
            return item

    def wait(self, timeout: float) -> bool:
        """Wait up to ``timeout`` s for a message in any ring (or :meth:`close`); True when there is one."""
        with self._cond:
            self._cond.wait_for(lambda: self._closed or any(self._rings.values()), timeout)
            return any(self._rings.values())

    def close(self) -> None:
        """Wake every waiter; from now on a full ring drops its oldest message even under ``block``."""
        with self._cond:
            self._closed = True
            self._cond.notify_all()

    def __len__(self) -> int:
        with self._cond:
            return sum(len(r) for r in self._rings.values())


__all__ = ["POLICIES", "BoundedQueue", "Policy", "QueueWorker", "ReceiveRings"]
