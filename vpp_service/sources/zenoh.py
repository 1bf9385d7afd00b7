"""Zenoh source: receive wire-format v1 frames from cameras on the network.

Subscribes with a callback that decodes and validates each message
(:mod:`vpp_service.transport.wire`) and buffers the valid ones in the network
sources' one receive ring type (:class:`~vpp_service.queueing.ReceiveRings`,
``ring_size`` per topic). A bad message is rejected (counted, reason reported)
and never enters a ring, so junk cannot displace valid frames; the source keeps
serving. This source's thread wakes as soon as a message is queued, drains the
rings, joins separate-topics parts and emits frames. The callback's size bound,
the rings, the drain loop and their counts are the network sources' shared part
(:class:`~vpp_service.sources.network.NetworkSource`); this module adds the wire
decoding and the topics' layout.

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
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import partial
from typing import TYPE_CHECKING, Annotated, Any, Literal

from vpp_service.frame import StereoFrame
from vpp_service.settings import Options, Range, reject
from vpp_service.sources.base import SOURCES, Reject, SourceContext
from vpp_service.sources.network import NetworkSource, Refused
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
class ZenohSource(NetworkSource[_Received]):
    """Frames from Zenoh (see the module docstring). Needs ``context.session``."""

    Options = ZenohSourceOptions
    options: ZenohSourceOptions
    received_at = "drain"  # a message a ring drops is counted in ring_dropped only

    def __init__(self, options: ZenohSourceOptions, context: SourceContext) -> None:
        limits = wire.WireLimits(
            max_message_bytes=int(options.max_message_mb * 1024 * 1024), max_pixels=options.max_pixels
        )
        super().__init__(options, context, max_message_bytes=limits.max_message_bytes, poll_s=options.poll_s)
        self._subs: dict[str, zenoh.Subscriber[None]] = {}
        self._limits = limits
        self.sync: Synchronizer[wire.Part] | None = None
        self._counters.update({"sync_dropped": 0, "sync_inconsistent": 0})

    def open(self) -> None:
        """Declare the subscribers on the service's session."""
        import zenoh

        session = self.session("zenoh")
        o = self.options
        parts = (
            ["frame"] if o.topics == "frame" else (["left", "right", "depth"] if o.with_depth else ["left", "right"])
        )
        self.open_rings({part: o.ring_sizes.get(part, o.ring_size) for part in parts})
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

    def _too_large(self, size: int) -> Refused:
        return Refused("too_large", f"message: {size} bytes exceeds the limit of {self.max_message_bytes}")

    def _topic_name(self, topic: str, sample: zenoh.Sample) -> str:
        return str(sample.key_expr)

    def _admit(self, topic: str, sample: zenoh.Sample, recv_ns: int) -> _Received:
        """Decode and validate in the callback: only a valid frame or part takes a ring slot."""
        t0 = time.perf_counter()
        try:
            payload = sample.payload.to_bytes()
            value: wire.Part | StereoFrame = (
                wire.decode_frame(payload, self._limits, metric_map=False)
                if topic == "frame"
                else wire.decode_part(payload, topic, self._limits)
            )
        except wire.WireError as exc:
            raise Refused("wire", str(exc)) from exc
        return _Received(str(sample.key_expr), value, recv_ns, (time.perf_counter() - t0) * 1e3)

    def _handle(self, topic: str, item: _Received, reject: Reject) -> list[StereoFrame]:
        """The frame a message completes: itself, or a separate-topics set the synchronizer joined."""
        t0 = time.perf_counter()
        if isinstance(item.value, StereoFrame):
            frame = item.value
        else:
            p = item.value
            assert self.sync is not None
            before, inconsistent = self.sync.dropped, self.sync.inconsistent
            joined = self.sync.add(topic, p.seq, p.stamp_ns, p)
            self.count("sync_dropped", self.sync.dropped - before)
            self.count("sync_inconsistent", self.sync.inconsistent - inconsistent)
            if joined is None:
                return []
            try:  # the synchronizer only joins parts that fit; this guards the contract
                frame = wire.assemble(joined["left"], joined["right"], joined.get("depth"))
            except wire.WireError as exc:
                self.count("rejected")
                reject(f"{item.key_expr}: {exc}")
                return []
        frame.meta["recv_ns"] = item.recv_ns
        frame.meta["timing_ms"] = {"decode": item.decode_ms + (time.perf_counter() - t0) * 1e3}
        return [frame]

    def close(self) -> None:
        """Undeclare the subscribers (the session belongs to the service)."""
        import zenoh

        for sub in self._subs.values():
            with contextlib.suppress(zenoh.ZError):  # already undeclared
                sub.undeclare()
        self._subs.clear()

    def stats(self) -> dict[str, Any]:
        """Counters (``received``, ``ring_dropped``, ``sync_dropped``, ``sync_inconsistent``, base ones), ``sync``."""
        out = super().stats()
        if self.sync is not None:
            out["sync"] = self.sync.stats()
        return out

    def losses(self) -> dict[str, int]:
        """Valid messages lost in this source, by cause: the ring (``latest``), the synchronizer."""
        c = self.stats()
        return {
            **super().losses(),
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
