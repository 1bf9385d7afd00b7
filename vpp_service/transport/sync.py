"""Separate-topics synchronizer: join left / right / depth messages into frames.

Like ROS ``message_filters``: :class:`Synchronizer` keeps a bounded queue per
topic (``queue_size``) and emits a set once every topic has a matching message.

- ``exact``: messages match when their ``seq`` is equal (ROS ``TimeSynchronizer``
  keyed by sequence number).
- ``approximate``: messages match when every stamp lies within
  ``threshold_ns`` of the newest message's stamp (DepthAI's sync threshold); the
  closest candidate per topic is chosen.

On a match, older messages still queued on any topic can never be matched in an
in-order stream: they are dropped and counted, as are messages evicted from a
full queue. Thread-safe.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Generic, TypedDict, TypeVar

T = TypeVar("T")


class SyncStats(TypedDict):
    """Counters of a :class:`Synchronizer` (see :meth:`Synchronizer.stats`)."""

    matched: int
    dropped: int
    pending: dict[str, int]


@dataclass
class _Item(Generic[T]):
    seq: int
    stamp_ns: int
    value: T


class Synchronizer(Generic[T]):
    """Join messages of several topics into synchronized sets.

    Parameters
    ----------
    topics : sequence of str
        Topic (part) names, e.g. ``("left", "right", "depth")``; at least 2, unique.
    mode : {"exact", "approximate"}
        Matching rule (see the module docstring).
    queue_size : int
        Messages kept per topic while waiting for partners (>= 1).
    threshold_ns : int
        Largest stamp difference inside an approximate set (>= 0).
    """

    def __init__(
        self, topics: Sequence[str], mode: str = "exact", queue_size: int = 10, threshold_ns: int = 20_000_000
    ) -> None:
        topics = tuple(topics)
        if len(topics) < 2 or len(set(topics)) != len(topics) or not all(isinstance(t, str) and t for t in topics):
            raise ValueError(f"topics must be at least 2 unique non-empty names, got {topics!r}")
        if mode not in ("exact", "approximate"):
            raise ValueError(f"mode must be 'exact' or 'approximate', got {mode!r}")
        if isinstance(queue_size, bool) or not isinstance(queue_size, int) or queue_size < 1:
            raise ValueError(f"queue_size must be an integer >= 1, got {queue_size!r}")
        if isinstance(threshold_ns, bool) or not isinstance(threshold_ns, int) or threshold_ns < 0:
            raise ValueError(f"threshold_ns must be an integer >= 0, got {threshold_ns!r}")
        self.topics = topics
        self.mode = mode
        self.queue_size = queue_size
        self.threshold_ns = threshold_ns
        self._queues: dict[str, deque[_Item[T]]] = {t: deque() for t in topics}
        self._lock = threading.Lock()
        self.matched = 0
        self.dropped = 0

    def add(self, topic: str, seq: int, stamp_ns: int, value: T) -> dict[str, T] | None:
        """Offer one message; returns ``{topic: value}`` when it completes a set, else None.

        Raises
        ------
        ValueError
            Unknown ``topic``.
        """
        if topic not in self._queues:
            raise ValueError(f"topic must be one of {list(self.topics)}, got {topic!r}")
        item = _Item(int(seq), int(stamp_ns), value)
        with self._lock:
            q = self._queues[topic]
            q.append(item)
            if len(q) > self.queue_size:
                q.popleft()
                self.dropped += 1
            chosen = self._match_exact(item) if self.mode == "exact" else self._match_approx(topic, item)
            if chosen is None:
                return None
            out = {}
            for t, it in chosen.items():
                q = self._queues[t]
                # drop everything up to and including the chosen item
                while q:
                    head = q.popleft()
                    if head is it:
                        break
                    self.dropped += 1
                out[t] = it.value
            self.matched += 1
            return out

    def _match_exact(self, item: _Item[T]) -> dict[str, _Item[T]] | None:
        chosen = {}
        for t, q in self._queues.items():
            hit = next((it for it in q if it.seq == item.seq), None)
            if hit is None:
                return None
            chosen[t] = hit
        return chosen

    def _match_approx(self, topic: str, item: _Item[T]) -> dict[str, _Item[T]] | None:
        chosen = {topic: item}
        for t, q in self._queues.items():
            if t == topic:
                continue
            best = min(q, key=lambda it: abs(it.stamp_ns - item.stamp_ns), default=None)
            if best is None or abs(best.stamp_ns - item.stamp_ns) > self.threshold_ns:
                return None
            chosen[t] = best
        stamps = [it.stamp_ns for it in chosen.values()]
        if max(stamps) - min(stamps) > self.threshold_ns:
            return None
        return chosen

    def pending(self) -> dict[str, int]:
        """Messages waiting per topic."""
        with self._lock:
            return {t: len(q) for t, q in self._queues.items()}

    def stats(self) -> SyncStats:
        """Counters: matched sets, dropped messages, pending per topic."""
        return {"matched": self.matched, "dropped": self.dropped, "pending": self.pending()}


__all__ = ["SyncStats", "Synchronizer"]
