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

An optional ``consistent(set) -> bool`` check (e.g. image and depth sizes agree)
is applied to every candidate set: a set that fails it is never emitted and
never consumes its parts, so a forged message carrying another frame's ``seq``
cannot destroy that frame. When several messages of a topic are candidates (the
genuine one and a forgery), every combination is tried; the messages passed
over on a match are counted in ``inconsistent``.
"""

from __future__ import annotations

import itertools
import threading
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Generic, TypedDict, TypeVar

T = TypeVar("T")


class SyncStats(TypedDict):
    """Counters of a :class:`Synchronizer` (see :meth:`Synchronizer.stats`)."""

    matched: int
    dropped: int
    inconsistent: int
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
    consistent : callable or None
        ``consistent({topic: value}) -> bool``: a candidate set failing it is not emitted.
    max_candidates : int
        Combinations tried per offered message (bounds the work a flood of same-``seq`` forgeries can cause).
    """

    def __init__(
        self,
        topics: Sequence[str],
        mode: str = "exact",
        queue_size: int = 10,
        threshold_ns: int = 20_000_000,
        *,
        consistent: Callable[[Mapping[str, T]], bool] | None = None,
        max_candidates: int = 64,
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
        if isinstance(max_candidates, bool) or not isinstance(max_candidates, int) or max_candidates < 1:
            raise ValueError(f"max_candidates must be an integer >= 1, got {max_candidates!r}")
        self.topics = topics
        self.mode = mode
        self.queue_size = queue_size
        self.threshold_ns = threshold_ns
        self._queues: dict[str, deque[_Item[T]]] = {t: deque() for t in topics}
        self.consistent = consistent
        self.max_candidates = max_candidates
        self._lock = threading.Lock()
        self.matched = 0
        self.dropped = 0
        self.inconsistent = 0

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
            chosen = self._match(topic, item)
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
                    self._count_unused(head, it)
                out[t] = it.value
            self.matched += 1
            return out

    def _count_unused(self, head: _Item[T], chosen: _Item[T]) -> None:
        """A message passed over by a match: a same-``seq`` rival of the chosen one is inconsistent, else dropped."""
        if self.mode == "exact" and head.seq == chosen.seq:
            self.inconsistent += 1
        else:
            self.dropped += 1

    def _candidates(self, topic: str, item: _Item[T]) -> dict[str, list[_Item[T]]] | None:
        """Per topic, the messages that may join ``item`` (best first); None when a topic has none."""
        out: dict[str, list[_Item[T]]] = {}
        for t, q in self._queues.items():
            if t == topic:
                out[t] = [item]
            elif self.mode == "exact":
                out[t] = [it for it in q if it.seq == item.seq]
            else:
                near = [it for it in q if abs(it.stamp_ns - item.stamp_ns) <= self.threshold_ns]
                out[t] = sorted(near, key=lambda it: abs(it.stamp_ns - item.stamp_ns))
            if not out[t]:
                return None
        return out

    def _match(self, topic: str, item: _Item[T]) -> dict[str, _Item[T]] | None:
        cands = self._candidates(topic, item)
        if cands is None:
            return None
        names = list(cands)
        for combo in itertools.islice(itertools.product(*cands.values()), self.max_candidates):
            chosen = dict(zip(names, combo, strict=True))
            if self.mode == "approximate":
                stamps = [it.stamp_ns for it in combo]
                if max(stamps) - min(stamps) > self.threshold_ns:
                    continue
            if self.consistent is None or self.consistent({t: it.value for t, it in chosen.items()}):
                return chosen
        return None

    def pending(self) -> dict[str, int]:
        """Messages waiting per topic."""
        with self._lock:
            return {t: len(q) for t, q in self._queues.items()}

    def stats(self) -> SyncStats:
        """Counters: matched sets, dropped and inconsistent messages, pending per topic."""
        return {
            "matched": self.matched,
            "dropped": self.dropped,
            "inconsistent": self.inconsistent,
            "pending": self.pending(),
        }


__all__ = ["SyncStats", "Synchronizer"]
