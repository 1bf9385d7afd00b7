"""Zenoh source: receive wire-format v1 frames from cameras on the network.

Subscribes with a callback that decodes and validates each message
(:mod:`vpp_service.transport.wire`) and buffers the valid ones in the network
sources' one receive ring type (:class:`~vpp_service.queueing.ReceiveRings`,
``ring_size`` per topic). A bad message is rejected (counted, reason reported)
and never enters a ring, so junk cannot displace valid frames; the source keeps
serving. This source's thread wakes as soon as a message is queued, drains the
rings, joins separate-topics parts and emits frames.

The callback runs directly on Zenoh's receive thread under both input
policies (no channel in between: an indirect callback's channel would buffer
seconds of frames, and under a junk flood its Python thread, always busy,
starves the processing thread of the interpreter while valid frames queue
behind the junk). A peer sending faster than messages are checked is held back
by the link, where a publisher using ``DROP`` loses its own surplus.

When the ring is full, the pipeline's input policy (:attr:`Source.input_policy`)
decides: ``latest`` drops the oldest sample (counted in ``ring_dropped``);
``block`` makes the callback wait for room, which holds the link back and with
it the publisher. With reliable transport and ``CongestionControl.BLOCK`` on
the publisher nothing is lost end to end (a publisher using ``DROP`` loses
samples in its own session, where no counter of this service can see them). While the link is held back,
other traffic on it waits too (``@status`` answers within about a frame time).

Metric depth points in an ``in/frame`` message arrive as their disparity only
(:func:`~vpp_service.transport.wire.decode_frame` with ``metric_map=False``):
the fusion and the sinks read that map, and building the metric one as well
cost a second H x W map per frame.

Topics: ``<prefix>/<rig>/in/frame`` (default), or with ``topics = "separate"``
``in/left``, ``in/right`` and ``in/depth`` joined by
:class:`vpp_service.transport.sync.Synchronizer` (``sync = "exact"`` by seq or
``"approximate"`` by stamp within ``sync_threshold_ms``). A set whose parts do
not fit together (image and depth sizes differ) is never emitted and does not
consume its parts: a forged part carrying another frame's ``seq`` is counted as
``inconsistent`` and the genuine frame still goes through.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import partial
from typing import TYPE_CHECKING, Annotated, Any, Literal

from vpp_service.frame import StereoFrame
from vpp_service.queueing import ReceiveRings
from vpp_service.settings import Options, Range, reject
from vpp_service.sources.base import SOURCES, Emit, Reject, Source, SourceContext
from vpp_service.transport import wire
from vpp_service.transport.sync import Synchronizer

if TYPE_CHECKING:
    import zenoh


@dataclass(frozen=True)
class ZenohSourceOptions(Options):
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
    sync_queue_size: Annotated[int, Range(1)] = 10
    sync_threshold_ms: Annotated[float, Range(0.0)] = 20.0
    ring_size: Annotated[int, Range(1)] = 4
    ring_sizes: dict[str, int] = field(default_factory=dict)
    max_message_mb: Annotated[float, Range(0.0, 4096.0, lo_open=True)] = 64.0
    max_pixels: Annotated[int, Range(1, 1 << 28)] = wire.DEFAULT_LIMITS.max_pixels
    poll_s: Annotated[float, Range(0.0, 1.0, lo_open=True)] = 0.05

    def cross_check(self) -> None:
        """``ring_sizes``: known topics, sizes >= 1, with ``topics = "separate"`` only."""
        for part, n in self.ring_sizes.items():
            if part not in ("left", "right", "depth"):
                raise reject("ring_sizes", part, "keys among 'depth', 'left', 'right'")
            if isinstance(n, bool) or not isinstance(n, int) or n < 1:
                raise reject(f"ring_sizes.{part}", n, ">= 1 (an integer)")
        if self.ring_sizes and self.topics != "separate":
            raise reject("ring_sizes", self.ring_sizes, '{} unless topics = "separate" (use ring_size)')


@dataclass(frozen=True)
class _Received:
    """A decoded, valid message waiting in a ring: a whole frame or a separate-topics part."""

    key_expr: str
    value: wire.Part | StereoFrame
    recv_ns: int
    decode_ms: float


@SOURCES.register("zenoh")
class ZenohSource(Source):
    """Frames from Zenoh (see the module docstring). Needs ``context.session``."""

    Options = ZenohSourceOptions
    options: ZenohSourceOptions
    needs_session = True
    network = True  # a live camera on the network: a service that resumes after a restart

    def __init__(self, options: ZenohSourceOptions, context: SourceContext) -> None:
        super().__init__(options, context)
        self._subs: dict[str, zenoh.Subscriber[None]] = {}
        self._limits = wire.WireLimits(
            max_message_bytes=int(options.max_message_mb * 1024 * 1024), max_pixels=options.max_pixels
        )
        self._rings: ReceiveRings[_Received] | None = None  # one ring per topic, built at open
        self._reject: Reject | None = None
        self.sync: Synchronizer[wire.Part] | None = None
        self._counters.update({"received": 0, "sync_dropped": 0, "sync_inconsistent": 0})

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
        self._rings = ReceiveRings({part: o.ring_sizes.get(part, o.ring_size) for part in parts}, self.input_policy)
        if o.topics == "separate":
            self.sync = Synchronizer(
                parts, o.sync, o.sync_queue_size, int(o.sync_threshold_ms * 1e6), consistent=_parts_fit
            )
        for part in parts:
            key = wire.topic(self.context.prefix, self.context.rig, f"in/{part}")
            # on Zenoh's receive thread (see the module docstring): block's wait for room holds the link back with
            # no queue in between, and a junk flood is held back at the link instead of queueing ahead of frames
            handler = zenoh.handlers.Callback(partial(self._on_sample, part), indirect=False)
            self._subs[part] = session.declare_subscriber(key, handler)

    def waits_on(self) -> str:
        """The key expressions subscribed to."""
        parts = self._rings.keys if self._rings is not None else []
        return ", ".join(wire.topic(self.context.prefix, self.context.rig, f"in/{part}") for part in parts)

    def start(self, emit: Emit, reject: Reject | None = None, on_finished: Callable[[], None] | None = None) -> None:
        """Start the receive thread; ``reject`` also hears of messages the subscriber callback turns away."""
        self._reject = reject
        super().start(emit, reject, on_finished)

    def _on_sample(self, part: str, sample: zenoh.Sample) -> None:
        """Subscriber callback: decode and validate, buffer what is valid, wake the receive thread.

        An oversized message is rejected by its length before its payload is
        copied. It runs on Zenoh's receive thread; under the ``block`` input policy a
        full ring makes it wait for room (back-pressure through Zenoh); under
        ``latest`` it never waits (the oldest sample is dropped and counted).
        """
        recv_ns = time.monotonic_ns()  # for durations (latency): a monotonic clock, immune to clock steps
        n = len(sample.payload)
        if n > self._limits.max_message_bytes:  # by its length, before the payload is copied out of Zenoh
            self.count("received")
            self.count("rejected")
            if self._reject is not None:
                self._reject(
                    f"{sample.key_expr}: message: {n} bytes exceeds the limit of {self._limits.max_message_bytes}"
                )
            return
        t0 = time.perf_counter()
        try:
            payload = sample.payload.to_bytes()
            value: wire.Part | StereoFrame = (
                wire.decode_frame(payload, self._limits, metric_map=False)
                if part == "frame"
                else wire.decode_part(payload, part, self._limits)
            )
        except wire.WireError as exc:
            self.count("received")  # received and rejected here; the valid ones count as received when drained
            self.count("rejected")
            if self._reject is not None:
                self._reject(f"{sample.key_expr}: {exc}")
            return
        assert self._rings is not None  # subscribed only after open built them
        self._rings.put(part, _Received(str(sample.key_expr), value, recv_ns, (time.perf_counter() - t0) * 1e3))

    def run(self, emit: Emit, reject: Reject) -> None:
        """Drain the rings, decode, validate, synchronize and emit until stopped."""
        rings = self._rings
        assert rings is not None  # run after open
        while not self.stopping():
            got = False
            for part in rings.keys:
                sample = rings.take(part)
                if sample is None:
                    continue
                got = True
                self.count("received")
                self._handle(part, sample, emit, reject)
            if not got:
                rings.wait(self.options.poll_s)

    def request_stop(self) -> None:
        """Ask the receive thread to stop and wake it, and every callback waiting for room (safe from any thread)."""
        super().request_stop()
        if self._rings is not None:
            self._rings.close()

    def stop(self, timeout: float = 5.0) -> None:
        """Wake the receive thread and the callbacks, stop within ``timeout`` seconds, undeclare the subscribers."""
        if self._rings is not None:
            self._rings.close()
        super().stop(timeout)

    def _handle(self, part: str, item: _Received, emit: Emit, reject: Reject) -> None:
        t0 = time.perf_counter()
        if isinstance(item.value, StereoFrame):
            frame = item.value
        else:
            p = item.value
            assert self.sync is not None
            before, inconsistent = self.sync.dropped, self.sync.inconsistent
            joined = self.sync.add(part, p.seq, p.stamp_ns, p)
            self.count("sync_dropped", self.sync.dropped - before)
            self.count("sync_inconsistent", self.sync.inconsistent - inconsistent)
            if joined is None:
                return
            try:  # the synchronizer only joins parts that fit; this guards the contract
                frame = wire.assemble(joined["left"], joined["right"], joined.get("depth"))
            except wire.WireError as exc:
                self.count("rejected")
                reject(f"{item.key_expr}: {exc}")
                return
        frame.meta["recv_ns"] = item.recv_ns
        frame.meta["timing_ms"] = {"decode": item.decode_ms + (time.perf_counter() - t0) * 1e3}
        self.count("emitted")
        emit(frame)

    def close(self) -> None:
        """Undeclare the subscribers (the session belongs to the service)."""
        import zenoh

        for sub in self._subs.values():
            with contextlib.suppress(zenoh.ZError):  # already undeclared
                sub.undeclare()
        self._subs.clear()

    def stats(self) -> dict[str, Any]:
        """Counters (``received``, ``ring_dropped``, ``sync_dropped``, ``sync_inconsistent``, base ones), ``sync``."""
        out: dict[str, Any] = super().stats()
        out["ring_dropped"] = self._rings.dropped_total if self._rings is not None else 0
        if self.sync is not None:
            out["sync"] = self.sync.stats()
        return out

    def losses(self) -> dict[str, int]:
        """Valid messages lost in this source, by cause: the ring (``latest``), the synchronizer."""
        c = self.stats()
        return {
            "source_ring": c["ring_dropped"],
            "sync": c["sync_dropped"],
            "sync_inconsistent": c["sync_inconsistent"],
        }


def _parts_fit(parts: Mapping[str, wire.Part]) -> bool:
    """Whether separate-topics parts make one frame (same image sizes, depth of the image's size)."""
    try:
        wire.assemble(parts["left"], parts["right"], parts.get("depth"))
    except (wire.WireError, ValueError):
        return False
    return True


__all__ = ["ZenohSource", "ZenohSourceOptions"]
