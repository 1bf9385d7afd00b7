"""Zenoh source: receive wire-format v1 frames from cameras on the network.

Subscribes with a callback that only appends the sample to a bounded ring
(``ring_size`` per topic; when the service falls behind the oldest samples are
dropped and counted in ``ring_dropped``) and signals an event: no decoding and
no blocking in Zenoh's thread.  This source's thread wakes on that event (no
polling delay), drains the rings, decodes and validates every message
(:mod:`vpp_service.transport.wire`) and emits frames; a bad message is rejected
(counted, reason reported) and the source keeps serving.

Topics: ``<prefix>/<rig>/in/frame`` (default), or with ``topics = "separate"``
``in/left``, ``in/right`` and ``in/depth`` joined by
:class:`vpp_service.transport.sync.Synchronizer` (``sync = "exact"`` by seq or
``"approximate"`` by stamp within ``sync_threshold_ms``).
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from functools import partial
from typing import TYPE_CHECKING, Any, Literal

from vpp_service.sources.base import SOURCES, Emit, Reject, Source, SourceContext
from vpp_service.transport import wire
from vpp_service.transport.sync import Synchronizer

if TYPE_CHECKING:
    import zenoh


@dataclass(frozen=True)
class ZenohSourceOptions:
    """Options of the ``zenoh`` source.

    Attributes
    ----------
    topics : {"frame", "separate"}
        One message per frame on ``in/frame``, or separate ``in/left``,
        ``in/right``, ``in/depth`` topics.
    with_depth : bool
        In separate mode, whether ``in/depth`` is part of every set (False:
        frames are assembled from left + right only and carry no depth).
    sync : {"exact", "approximate"}
        Separate-topics matching rule.
    sync_queue_size : int
        Messages kept per topic while waiting for partners.
    sync_threshold_ms : float
        Approximate sync: largest stamp difference inside a set.
    ring_size : int
        Samples buffered per subscribed topic (oldest dropped and counted).
    ring_sizes : dict
        Per-topic overrides of ``ring_size`` in separate-topics mode, e.g.
        ``{depth = 16}`` for a sensor that runs ahead of the cameras.
    max_message_mb : float
        Messages larger than this are rejected (and counted) in the Zenoh
        callback, before the payload is copied out or buffered; keep the
        session's ``[zenoh] max_message_mb`` at least as large.
    max_pixels : int
        Largest image / depth map (``h * w``) accepted, checked before
        anything that size is allocated or decoded (PNG/JPEG sizes are read
        from the stream's header); the default admits full-resolution
        Middlebury (2964 x 1988).
    poll_s : float
        Longest idle sleep of the receive thread between checks for a stop
        request; arriving samples wake it at once.
    """

    topics: Literal["frame", "separate"] = "frame"
    with_depth: bool = True
    sync: Literal["exact", "approximate"] = "exact"
    sync_queue_size: int = 10
    sync_threshold_ms: float = 20.0
    ring_size: int = 4
    ring_sizes: dict[str, int] = field(default_factory=dict)
    max_message_mb: float = 64.0
    max_pixels: int = wire.DEFAULT_LIMITS.max_pixels
    poll_s: float = 0.05

    def __post_init__(self) -> None:
        if self.sync_queue_size < 1:
            raise ValueError(f"sync_queue_size must be >= 1, got {self.sync_queue_size}")
        if not self.sync_threshold_ms >= 0:
            raise ValueError(f"sync_threshold_ms must be >= 0, got {self.sync_threshold_ms}")
        if self.ring_size < 1:
            raise ValueError(f"ring_size must be >= 1, got {self.ring_size}")
        for part, n in self.ring_sizes.items():
            if part not in ("left", "right", "depth"):
                raise ValueError(f"ring_sizes: unknown topic {part!r}; known: depth, left, right")
            if isinstance(n, bool) or not isinstance(n, int) or n < 1:
                raise ValueError(f"ring_sizes.{part} must be an int >= 1, got {n!r}")
        if self.ring_sizes and self.topics != "separate":
            raise ValueError('ring_sizes: only for topics = "separate" (use ring_size)')
        if not 0 < self.max_message_mb <= 4096:
            raise ValueError(f"max_message_mb must be in (0, 4096], got {self.max_message_mb}")
        if isinstance(self.max_pixels, bool) or not 1 <= self.max_pixels <= 1 << 28:
            raise ValueError(f"max_pixels must be in [1, {1 << 28}], got {self.max_pixels}")
        if not 0 < self.poll_s <= 1:
            raise ValueError(f"poll_s must be in (0, 1], got {self.poll_s}")


@SOURCES.register("zenoh")
class ZenohSource(Source):
    """Frames from Zenoh (see the module docstring). Needs ``context.session``."""

    Options = ZenohSourceOptions
    options: ZenohSourceOptions
    needs_session = True

    def __init__(self, options: ZenohSourceOptions, context: SourceContext) -> None:
        super().__init__(options, context)
        self._subs: dict[str, zenoh.Subscriber[None]] = {}
        self._limits = wire.WireLimits(
            max_message_bytes=int(options.max_message_mb * 1024 * 1024), max_pixels=options.max_pixels
        )
        self._reject: Reject | None = None  # run()'s reject callback, for oversized messages seen in Zenoh's thread
        self._rings: dict[str, deque[zenoh.Sample]] = {}
        self._ring_lock = threading.Lock()
        self._arrived = threading.Event()
        self.sync: Synchronizer[wire.Part] | None = None
        self._counters.update({"received": 0, "ring_dropped": 0, "sync_dropped": 0})

    def open(self) -> None:
        """Declare the subscribers on the service's session."""
        import zenoh

        session: zenoh.Session | None = self.context.session
        if session is None:
            raise ValueError("source.zenoh: needs an open zenoh session (service.zenoh section)")
        o = self.options
        parts = (
            ["frame"] if o.topics == "frame" else (["left", "right", "depth"] if o.with_depth else ["left", "right"])
        )
        for part in parts:
            key = wire.topic(self.context.prefix, self.context.rig, f"in/{part}")
            self._rings[part] = deque(maxlen=o.ring_sizes.get(part, o.ring_size))
            self._subs[part] = session.declare_subscriber(key, zenoh.handlers.Callback(partial(self._on_sample, part)))
        if o.topics == "separate":
            self.sync = Synchronizer(parts, o.sync, o.sync_queue_size, int(o.sync_threshold_ms * 1e6))

    def _on_sample(self, part: str, sample: zenoh.Sample) -> None:
        """Zenoh callback: buffer the sample and wake the receive thread (never blocks long).

        An oversized message is rejected here, by its length, before its payload is copied or buffered.
        """
        n = len(sample.payload)
        if n > self._limits.max_message_bytes:
            self._counters["received"] += 1
            self._counters["rejected"] += 1
            if self._reject is not None:
                self._reject(
                    f"{sample.key_expr}: message: {n} bytes exceeds the limit of {self._limits.max_message_bytes}"
                )
            return
        ring = self._rings[part]
        with self._ring_lock:
            if len(ring) == ring.maxlen:
                self._counters["ring_dropped"] += 1
            ring.append(sample)
        self._arrived.set()

    def _next(self, part: str) -> zenoh.Sample | None:
        with self._ring_lock:
            ring = self._rings[part]
            return ring.popleft() if ring else None

    def run(self, emit: Emit, reject: Reject) -> None:
        """Drain the rings, decode, validate, synchronize and emit until stopped."""
        self._reject = reject
        while not self.stopping():
            self._arrived.clear()  # before draining: a later sample sets it again
            got = False
            for part in list(self._rings):
                sample = self._next(part)
                if sample is None:
                    continue
                got = True
                self._counters["received"] += 1
                self._handle(part, sample, emit, reject)
            if not got:
                self._arrived.wait(self.options.poll_s)

    def request_stop(self) -> None:
        """Ask the receive thread to stop and wake it (safe from any thread)."""
        super().request_stop()
        self._arrived.set()

    def stop(self, timeout: float = 5.0) -> None:
        """Wake the receive thread, stop it within ``timeout`` seconds and undeclare the subscribers."""
        self._arrived.set()
        super().stop(timeout)

    def _handle(self, part: str, sample: zenoh.Sample, emit: Emit, reject: Reject) -> None:
        recv_ns = time.time_ns()
        t0 = time.perf_counter()
        try:
            payload = sample.payload.to_bytes()
            if part == "frame":
                frame = wire.decode_frame(payload, self._limits)
            else:
                p = wire.decode_part(payload, part, self._limits)
                assert self.sync is not None
                before = self.sync.dropped
                joined = self.sync.add(part, p.seq, p.stamp_ns, p)
                self._counters["sync_dropped"] += self.sync.dropped - before
                if joined is None:
                    return
                frame = wire.assemble(joined["left"], joined["right"], joined.get("depth"))
        except wire.WireError as exc:
            self._counters["rejected"] += 1
            reject(f"{sample.key_expr}: {exc}")
            return
        frame.meta["recv_ns"] = recv_ns
        frame.meta["timing_ms"] = {"decode": (time.perf_counter() - t0) * 1e3}
        self._counters["emitted"] += 1
        emit(frame)

    def close(self) -> None:
        """Undeclare the subscribers (the session belongs to the service)."""
        import zenoh

        for sub in self._subs.values():
            with contextlib.suppress(zenoh.ZError):  # already undeclared
                sub.undeclare()
        self._subs.clear()

    def stats(self) -> dict[str, Any]:
        """Counters (``received``, ``ring_dropped``, ``sync_dropped`` and the base ones), plus ``sync`` statistics."""
        out: dict[str, Any] = dict(self._counters)
        if self.sync is not None:
            out["sync"] = self.sync.stats()
        return out


__all__ = ["ZenohSource", "ZenohSourceOptions"]
