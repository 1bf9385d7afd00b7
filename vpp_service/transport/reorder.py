"""Put a stream back in ``seq`` order within a bounded window, counting gaps, late items and duplicates.

A rig's pool of workers (:mod:`vpp_service.service.pool`) answers frames in
parallel, so the union of their outputs arrives out of order, and a frame
taken over after a worker died arrives after newer ones. Consumers that need
order (``vpp-service view``, the files, record and Rerun sinks) pass what they
receive through a :class:`ReorderBuffer`:

- the first item waits like one after a hole (an earlier one may still come);
- an item whose ``seq`` is the next expected one is released at once, with
  every held item that follows it without a hole;
- a hole is waited for while fewer than ``window`` items are held and the
  oldest held item is younger than ``max_wait_s``; then the buffer skips it:
  each skipped ``seq`` is a **gap** (unless ``expected(seq)`` says it was never
  meant for this consumer, e.g. another worker's share);
- an item older than what was already released arrives **late**: it is released
  at once, out of order (a file named by ``seq`` is still worth writing), and
  counted; an item whose ``seq`` was already released or is already held is a
  **duplicate** (a frame answered twice in a pool): dropped and counted;
- a stream that restarts (``max(window, 8)`` late items in a row, e.g. a
  publisher restarted its ``seq`` at 0) resets the buffer (counted in ``resets``).

Memory is bounded by ``window`` held items plus ``window`` remembered ``seq``
values per released-set. Nothing here blocks or starts a thread: the consumer
calls :meth:`ReorderBuffer.poll` from its own loop to release items whose
wait expired, and :meth:`ReorderBuffer.flush` when it stops.
"""

from __future__ import annotations

import heapq
import itertools
import time
from collections import OrderedDict
from collections.abc import Callable
from typing import Generic, TypedDict, TypeVar

T = TypeVar("T")

#: Past a hole this long, every missing ``seq`` counts as a gap without asking ``expected``.
_MAX_SCAN = 1 << 16


class ReorderStats(TypedDict):
    """Counters of a :class:`ReorderBuffer`."""

    held: int
    released: int
    reordered: int
    gaps: int
    late: int
    duplicates: int
    resets: int


class ReorderBuffer(Generic[T]):
    """Release items in ``seq`` order within a bounded window (see the module docstring).

    Parameters
    ----------
    window : int
        At most this many items are held waiting for a hole to fill (>= 1).
    max_wait_s : float
        The longest an item is held for a hole before it (>= 0).
    expected : callable or None
        ``expected(seq)``: whether a missing ``seq`` counts as a gap (default: every ``seq``).
    clock : callable
        Monotonic seconds (tests pass their own).
    """

    def __init__(
        self,
        window: int = 16,
        max_wait_s: float = 0.5,
        expected: Callable[[int], bool] | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if isinstance(window, bool) or not isinstance(window, int) or window < 1:
            raise ValueError(f"window must be an int >= 1, got {window!r}")
        if not 0 <= max_wait_s <= 3600:
            raise ValueError(f"max_wait_s must be in [0, 3600], got {max_wait_s!r}")
        self.window = window
        self.max_wait_s = float(max_wait_s)
        self.expected = expected
        self.clock = clock
        self._heap: list[tuple[int, int, float, T]] = []  # (seq, arrival order, arrival time, item)
        self._held: set[int] = set()
        self._order = itertools.count()
        self._next: int | None = None  # the seq released next; None until the first release
        self._highest = -1  # the highest seq pushed so far
        self._recent: OrderedDict[int, None] = OrderedDict()  # seqs released late or in order, most recent
        self._late_run = 0
        self._counts = {"released": 0, "reordered": 0, "gaps": 0, "late": 0, "duplicates": 0, "resets": 0}

    def push(self, seq: int, item: T) -> list[tuple[int, T]]:
        """Add one item; returns the ``(seq, item)`` pairs released now, in the order to use them."""
        out: list[tuple[int, T]] = []
        if seq in self._held or seq in self._recent:
            self._counts["duplicates"] += 1
            return out
        if self._next is not None and seq < self._next:
            self._late_run += 1
            if self._late_run < max(self.window, 8):
                self._counts["late"] += 1
                self._remember(seq)
                self._counts["released"] += 1
                return [(seq, item)]
            # a restarted stream: release what is held, start over from this item
            out = self.flush()
            self._counts["resets"] += 1
            self._next, self._highest = None, -1
            self._recent.clear()
        self._late_run = 0
        if seq < self._highest:
            self._counts["reordered"] += 1
        self._highest = max(self._highest, seq)
        heapq.heappush(self._heap, (seq, next(self._order), self.clock(), item))
        self._held.add(seq)
        out += self._release(self.clock())
        return out

    def poll(self) -> list[tuple[int, T]]:
        """Release the items whose wait for a hole expired (call it from the consumer's loop)."""
        return self._release(self.clock())

    def flush(self) -> list[tuple[int, T]]:
        """Release everything held, in order (holes between them count as gaps)."""
        out: list[tuple[int, T]] = []
        while self._heap:
            out += self._skip_to_head()
            out += self._in_order()
        return out

    def stats(self) -> ReorderStats:
        """The counters and how many items are held now."""
        c = self._counts
        return {
            "held": len(self._heap),
            "released": c["released"],
            "reordered": c["reordered"],
            "gaps": c["gaps"],
            "late": c["late"],
            "duplicates": c["duplicates"],
            "resets": c["resets"],
        }

    # ------------------------------------------------------------ internals
    def _remember(self, seq: int) -> None:
        self._recent[seq] = None
        self._recent.move_to_end(seq)
        while len(self._recent) > 4 * self.window:
            self._recent.popitem(last=False)

    def _in_order(self) -> list[tuple[int, T]]:
        """Release the head while it is the next seq (and every unexpected hole before it)."""
        out: list[tuple[int, T]] = []
        while self._heap and self._next is not None:  # the first item waits like a hole: it may not be the first
            head = self._heap[0][0]
            if head > self._next and self.expected is not None:
                # holes that were never this consumer's are skipped at once, uncounted
                stop = min(head, self._next + _MAX_SCAN)
                while self._next < stop and not self.expected(self._next):
                    self._next += 1
            if head != self._next:
                break
            seq, _, _, item = heapq.heappop(self._heap)
            self._held.discard(seq)
            self._remember(seq)
            self._next = seq + 1
            self._counts["released"] += 1
            out.append((seq, item))
        return out

    def _skip_to_head(self) -> list[tuple[int, T]]:
        """Give up on the hole before the head: count it as gaps, make the head the next seq."""
        head = self._heap[0][0]
        if self._next is not None and head > self._next:
            if self.expected is None or head - self._next > _MAX_SCAN:
                self._counts["gaps"] += head - self._next
            else:
                self._counts["gaps"] += sum(1 for s in range(self._next, head) if self.expected(s))
        self._next = head
        return []

    def _release(self, now: float) -> list[tuple[int, T]]:
        out = self._in_order()
        while self._heap and (
            len(self._heap) > self.window or now - min(t for _, _, t, _ in self._heap) >= self.max_wait_s
        ):
            out += self._skip_to_head()
            out += self._in_order()
        return out


__all__ = ["ReorderBuffer", "ReorderStats"]
