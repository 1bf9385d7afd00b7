"""Zenoh sink: publish results on ``<prefix>/<rig>/out/<name>`` (wire format v1).

Outputs (``outputs`` option, lazy: only the listed ones are serialized).
``on_request`` lists outputs that are published only while someone subscribes
to them (Zenoh's matching status; default: the painted pair and the sparse
points, which ``vpp-service view`` shows), so they cost nothing otherwise.
``sparse`` carries the sparse input points. ``points`` is the point cloud: the
depth map's valid pixels on every ``points_stride``-th row and column, back-projected
into the rectified left camera (x y z float32 metres) with their colours (RGB uint8);
docs/wire-format.md gives the layout.

``confidence`` is the per-pixel confidence of the disparity (float32 0..1,
0 where there is no answer); the service computes it only when a sink lists
it (for matchers other than census-sgm it costs a second matching pass).

``disparity``, ``depth``, ``confidence`` (float32 maps) and ``points`` (the products) are
published at ``Priority.DATA``
with ``CongestionControl.DROP`` by default (``congestion_control`` option):
Zenoh's ``BLOCK`` would make the publisher wait for the slowest subscriber, so
one consumer that stops reading would slow every other consumer down to its
pace. With ``DROP`` such a consumer loses messages instead (Zenoh drops them
on that link, unseen by the publisher; a consumer counts its losses as gaps
in ``seq``). ``"block"`` suits a deployment whose consumers are all trusted
to keep up and must not lose a map. ``left_vpp`` / ``right_vpp`` and
``sparse`` (for viewing) always go at ``Priority.DATA_LOW`` with ``DROP``.

``write`` serializes and publishes one result, synchronously; the pipeline
runs it on this sink's own thread behind a queue of ``queue_size`` results
(:meth:`ZenohSink.queue_spec`; the oldest dropped and counted when full).
``close`` undeclares the publishers (the session belongs to the service).
"""

from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Annotated, Any, Literal

from vpp_service.frame import FusionResult
from vpp_service.settings import Each, NonEmpty, OneOf, Options, Range, Unique
from vpp_service.sinks.base import SINKS, QueueSpec, Sink, SinkContext
from vpp_service.timing import StageTimer
from vpp_service.transport import wire
from vpp_service.transport.backproject import DEFAULT_STRIDE, MAX_STRIDE
from vpp_service.transport.shm import ShmPutter

if TYPE_CHECKING:
    import zenoh


@dataclass(frozen=True)
class ZenohSinkOptions(Options):
    """Options of the ``zenoh`` sink.

    Attributes
    ----------
    outputs : list of str
        Which of ``disparity``, ``depth``, ``confidence``, ``left_vpp``, ``right_vpp``, ``sparse``,
        ``points`` to publish.
    on_request : list of str
        Outputs (not in ``outputs``) published only while a subscriber matches.
    image_enc : {"raw", "png", "jpeg"}
        Encoding of the ``left_vpp`` / ``right_vpp`` images.
    queue_size : int
        Results buffered between the pipeline and the publishing thread.
    shm_pool_mb : int
        Shared-memory pool the large outputs are published from
        (:mod:`vpp_service.transport.shm`); 0 = plain puts only.
    congestion_control : {"drop", "block"}
        Zenoh congestion control of ``disparity`` / ``depth`` / ``confidence`` / ``points``: ``drop`` (a
        consumer that does not read loses messages, the others keep their
        rate) or ``block`` (lossless, at the pace of the slowest consumer).
    points_stride : int
        ``points``: every ``points_stride``-th row and column of the depth map (1 = every
        pixel; the default 4 keeps a 720p cloud under 57 600 points).
    """

    outputs: Annotated[list[str], NonEmpty(), Unique(), Each(OneOf(*wire.OUTPUTS))] = field(
        default_factory=lambda: ["disparity", "depth"]
    )
    on_request: Annotated[list[str], Unique(), Each(OneOf(*wire.OUTPUTS))] = field(
        default_factory=lambda: ["left_vpp", "right_vpp", "sparse"]
    )
    image_enc: Literal["raw", "png", "jpeg"] = "png"
    queue_size: Annotated[int, Range(1)] = 4
    shm_pool_mb: Annotated[int, Range(0, 4096)] = 64
    congestion_control: Literal["drop", "block"] = "drop"
    points_stride: Annotated[int, Range(1, MAX_STRIDE)] = DEFAULT_STRIDE


def _matching(pub: zenoh.Publisher) -> bool:
    """Whether a subscriber matches ``pub`` (zenoh returns a MatchingStatus; its stubs say bool)."""
    status: object = pub.matching_status
    return bool(getattr(status, "matching", status))


@SINKS.register("zenoh")
class ZenohSink(Sink):
    """Publish results over Zenoh (see the module docstring). Needs ``context.session``."""

    Options = ZenohSinkOptions
    options: ZenohSinkOptions
    needs_session = True

    @classmethod
    def needs_depth(cls, options: ZenohSinkOptions) -> bool:
        """True when ``depth`` or ``points`` is among the published outputs."""
        return any(name in (*options.outputs, *options.on_request) for name in ("depth", "points"))

    @classmethod
    def needs_confidence(cls, options: ZenohSinkOptions) -> bool:
        """True when ``confidence`` is published (in ``outputs`` or ``on_request``)."""
        return "confidence" in options.outputs or "confidence" in options.on_request

    def __init__(self, options: ZenohSinkOptions, context: SinkContext) -> None:
        super().__init__(options, context)
        self._pubs: dict[str, zenoh.Publisher] = {}
        self._timer = StageTimer()  # per-result serialization / put durations (ms), medians in stats()
        self._putter = ShmPutter(options.shm_pool_mb)
        self._on_request: list[str] = []
        self._counters["unrequested"] = 0  # on_request outputs not serialized: nobody subscribed

    def queue_spec(self) -> QueueSpec:
        """``queue_size`` results wait for this sink (a full queue drops the oldest unless the pipeline blocks)."""
        return QueueSpec(size=self.options.queue_size)

    def open(self) -> None:
        """Declare one publisher per output."""
        import zenoh

        session: zenoh.Session | None = self.context.session
        if session is None:
            raise ValueError("sinks.zenoh: needs an open zenoh session (service.zenoh section)")
        o = self.options
        product = zenoh.CongestionControl.BLOCK if o.congestion_control == "block" else zenoh.CongestionControl.DROP
        self._on_request = [n for n in o.on_request if n not in o.outputs]
        for name in [*o.outputs, *self._on_request]:
            visual = name in ("left_vpp", "right_vpp", "sparse")
            self._pubs[name] = session.declare_publisher(
                wire.topic(self.context.prefix, self.context.rig, f"out/{name}"),
                congestion_control=zenoh.CongestionControl.DROP if visual else product,
                priority=zenoh.Priority.DATA_LOW if visual else zenoh.Priority.DATA,
            )

    def write(self, result: FusionResult) -> None:
        """Serialize and publish every output of one result.

        Raises
        ------
        RuntimeError
            If the sink is not open.
        """
        if not self._pubs:
            raise RuntimeError("zenoh sink: not open")
        enc_s = put_s = 0.0
        for name, pub in self._pubs.items():
            if name in self._on_request and not _matching(pub):
                self._counters["unrequested"] += 1
                continue  # nobody asked for it
            t0 = time.perf_counter()
            payload = wire.encode_output_parts(result, name, self.options.image_enc, self.options.points_stride)
            t1 = time.perf_counter()
            if payload is not None:
                self._putter.put(pub, payload)
            enc_s += t1 - t0
            put_s += time.perf_counter() - t1
        self._timer.add("encode", enc_s * 1e3)
        self._timer.add("put", put_s * 1e3)
        self.count("written")

    def close(self, timeout: float = 5.0) -> None:
        """Undeclare the publishers."""
        import zenoh

        for pub in self._pubs.values():
            with contextlib.suppress(zenoh.ZError):  # already undeclared
                pub.undeclare()
        self._pubs.clear()

    def stats(self) -> dict[str, Any]:
        """Counters plus ``timing_ms``: median ``encode`` / ``put`` time per result (recent window)."""
        out: dict[str, Any] = super().stats()
        out["shm"] = self._putter.stats()
        out["timing_ms"] = self._timer.medians()
        return out


__all__ = ["ZenohSink", "ZenohSinkOptions"]
