"""The pipeline's ledger: what became of every frame, and the ``@status`` figures built from it.

:class:`~vpp_service.service.pipeline.Pipeline` moves frames; the :class:`Ledger` counts what
became of them. Counters (``received``, ``rejected``, ``dropped``, ``processed``, ``published``,
``no_depth``, ``errors``, and ``sparse.see_through``: sparse points the fusion step's see-through
filter removed before VPP, :mod:`vpp_service.vpp.see_through`), per-stage timings (mean, p50,
p99 over a sliding window), the accuracy of the frames that carry ground truth and the recent
frame rate are what :meth:`Pipeline.status <vpp_service.service.pipeline.Pipeline.status>`
reports (a :class:`PipelineStatus`), which the service also serves as JSON on the
``<prefix>/<rig>/@status`` queryable (:class:`StatusReplies`).

Every loss of valid input or output anywhere is in one count: ``counters["dropped"]``
is the sum of ``status()["dropped"]`` (:meth:`Ledger.losses`), which names each cause
(``input_queue``, ``shutdown`` for frames and results still queued, or frames still being matched
(e.g. on a Triton server), when a stop that timed out abandons them, the source's own losses
such as ``source_ring`` and ``sync``, and ``sink.<Name>`` for each sink's: its full queue's drops
plus what the sink itself lost). Frames still queued when ``max_frames`` is reached were not
wanted: they are not counted as lost.

Without ``max_frames``, every received frame ends in exactly one count::

    received = rejected + processed + errors (of the process step)
               + dropped["input_queue"] + the frames under dropped["shutdown"]

and every processed frame is ``published`` or lost at a sink (``sink.<Name>``, ``shutdown``).

A rejected message is logged at most once per ``log_period_s`` (the lines in between are
counted and named in the next one), and so is a frame the process step failed on.
"""

from __future__ import annotations

import contextlib
import json
import logging
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any, Literal, NotRequired, TypedDict

import numpy as np

from vpp_service.frame import FusionResult
from vpp_service.metrics import answered_metrics
from vpp_service.queueing import Policy, QueueWorker
from vpp_service.timing import StageTimer

if TYPE_CHECKING:
    import zenoh

    from vpp_service.service.in_flight import InFlight
    from vpp_service.sources.base import Source

log = logging.getLogger(__name__)

#: The pipeline's counters (``counters`` in the status adds ``dropped``, the sum of every loss).
COUNTER_NAMES = ("received", "rejected", "processed", "published", "no_depth", "errors", "sparse.see_through")
#: ``@status`` replies within this many seconds of a snapshot reuse it (a query flood cannot load the service).
STATUS_SNAPSHOT_S = 0.1
#: Seconds over which ``fps`` is measured (a recent window: it falls to 0 when frames stop coming).
FPS_WINDOW_S = 5.0

#: Why a frame or result is lost at a stop (each counted under ``dropped["shutdown"]``):
#: ``refused``: the source emitted it while the pipeline was stopping (or it was taken from the queue
#: just as a stop gave up); ``abandoned``: it was being matched when a stop gave up waiting;
#: ``unsent``: a sink's queue refused its result while stopping (one per sink).
StopLoss = Literal["refused", "abandoned", "unsent"]


class QueueStatus(TypedDict):
    """Fill and drops of one pipeline queue (``Pipeline.status()["queues"][name]``)."""

    len: int
    size: int
    policy: Policy
    dropped: int
    high_water: int


class MetricsStatus(TypedDict):
    """Accuracy against ground truth (frames that carry it), means over the timing window.

    The three numbers of every report (:mod:`vpp_service.metrics`):
    ``bad2_answered_mean`` is bad-2 (percent) over the pixels with ground truth
    that got a value, ``density_mean`` the percentage of pixels with ground truth
    that got one, and ``bad2_filled_mean`` bad-2 with the holes filled first, as
    ``eval`` scores. ``last`` is the last frame's
    :func:`~vpp_service.metrics.compute_metrics` (raw: a pixel without
    a value counts as bad) plus the three. None until a frame with ground truth
    was processed.
    """

    last: dict[str, float]
    bad2_answered_mean: float | None
    density_mean: float | None
    bad2_filled_mean: float | None


class PipelineStatus(TypedDict):
    """What :meth:`Pipeline.status <vpp_service.service.pipeline.Pipeline.status>` reports (JSON-ready; ``@status``)."""

    rig: str
    prefix: str
    uptime_s: float
    counters: dict[str, int]
    dropped: dict[str, int]
    source_error: str | None
    config_error: str | None
    zenoh: dict[str, int] | None
    fps: float
    queues: dict[str, QueueStatus]
    timing_ms: dict[str, dict[str, float]]
    status_queries: dict[str, int]
    source: Mapping[str, object]
    sinks: dict[str, Mapping[str, object]]
    metrics: MetricsStatus
    #: What runs the matcher (``Pipeline.matcher_runtime``), when the process step says.
    matcher: NotRequired[dict[str, object]]
    network: NotRequired[Mapping[str, object]]


class Ledger:
    """The counters, losses, timings, accuracy and frame-rate windows of one pipeline (thread-safe).

    Parameters
    ----------
    timing_window : int
        Window (samples) of the timing and accuracy statistics (>= 1).
    log_period_s : float
        At most one rejected-input line, and one failed-frame line, per this many seconds (>= 0).

    Raises
    ------
    ValueError
        ``timing_window`` below 1 or ``log_period_s`` negative.
    """

    def __init__(self, timing_window: int = 200, log_period_s: float = 5.0) -> None:
        if not log_period_s >= 0:
            raise ValueError(f"log_period_s must be >= 0, got {log_period_s!r}")
        self.timer = StageTimer(timing_window)
        self.log_period_s = log_period_s
        self._lock = threading.Lock()
        self._counts = dict.fromkeys(COUNTER_NAMES, 0)
        self._stop_losses: dict[StopLoss, int] = {"refused": 0, "abandoned": 0, "unsent": 0}
        self._last_reject_log = 0.0
        self._suppressed = 0
        self._last_error_log = 0.0
        self._last_metrics: dict[str, float] = {}
        self._bad2_filled: deque[float] = deque(maxlen=timing_window)
        self._bad2_answered: deque[float] = deque(maxlen=timing_window)
        self._density: deque[float] = deque(maxlen=timing_window)
        self._done_at: deque[float] = deque(maxlen=10000)  # monotonic time of each processed frame (for fps)

    # ------------------------------------------------------------ counting
    def count(self, name: str, n: int = 1) -> None:
        """Add ``n`` to counter ``name`` (one of :data:`COUNTER_NAMES`).

        Raises
        ------
        KeyError
            ``name`` is not a counter.
        """
        with self._lock:
            if name not in self._counts:
                raise KeyError(f"unknown counter {name!r}; expected one of {', '.join(COUNTER_NAMES)}")
            self._counts[name] += n

    def get(self, name: str) -> int:
        """Counter ``name`` now (cheap enough to poll)."""
        with self._lock:
            return self._counts[name]

    def counts(self) -> dict[str, int]:
        """A snapshot of every counter (without ``dropped``, which :meth:`losses` gives)."""
        with self._lock:
            return dict(self._counts)

    def handled(self) -> int:
        """Frames processed or rejected (what ``max_frames`` counts)."""
        with self._lock:
            return self._counts["processed"] + self._counts["rejected"]

    def lost_at_stop(self, why: StopLoss, n: int = 1) -> None:
        """Count ``n`` frames or results lost to a stop (see :data:`StopLoss`; under ``shutdown``)."""
        with self._lock:
            self._stop_losses[why] += n

    def reject(self, reason: str) -> None:
        """Count one rejected message and log ``reason`` (at most once per :attr:`log_period_s`)."""
        self.count("rejected")
        now = time.monotonic()
        with self._lock:
            due = now - self._last_reject_log >= self.log_period_s
            suppressed = self._suppressed
            if due:
                self._last_reject_log, self._suppressed = now, 0
            else:
                self._suppressed += 1
        if due:
            extra = f" (+{suppressed} more since the last report)" if suppressed else ""
            log.warning("rejected input: %s%s", reason, extra)

    def failed(self, seq: int, exc: Exception) -> None:
        """Count one frame the process step failed on (``errors``) and log it (at most once per period)."""
        self.count("errors")
        now = time.monotonic()
        with self._lock:
            due = now - self._last_error_log >= self.log_period_s
            if due:
                self._last_error_log = now
        if due:
            log.error("processing frame seq=%s failed: %r", seq, exc)

    def processed(self, result: FusionResult) -> None:
        """Count a processed frame: its stage timings, accuracy, ``no_depth``, ``sparse.see_through``, fps."""
        for stage, ms in result.timing_ms.items():
            self.timer.add(stage, ms)
        if result.metrics:
            split = answered_metrics(result.metrics)
            self._last_metrics = {**result.metrics, **split}
            if "bad2_filled" in result.metrics:
                self._bad2_filled.append(result.metrics["bad2_filled"])
            if split:
                self._density.append(split["density"])
                if np.isfinite(split["bad2_answered"]):
                    self._bad2_answered.append(split["bad2_answered"])
        if result.frame.sparse_disparity is None and result.frame.sensor_depth is None:
            self.count("no_depth")
        if result.see_through:
            self.count("sparse.see_through", result.see_through)
        self.count("processed")
        self._done_at.append(time.monotonic())

    def published(self, result: FusionResult) -> None:
        """Count a result every sink has: ``published`` and its ``latency``.

        The latency runs from when this service received the frame (``meta["recv_ns"]``,
        :func:`time.monotonic_ns`), never from the sender's ``stamp_ns``, which any peer can set.
        """
        recv_ns = result.frame.meta.get("recv_ns")
        if isinstance(recv_ns, int):
            self.timer.add("latency", (time.monotonic_ns() - recv_ns) / 1e6)
        self.count("published")

    # ------------------------------------------------------------- figures
    def losses(
        self,
        source: Source,
        input_queue: QueueWorker[Any],
        sink_queues: Sequence[tuple[str, QueueWorker[Any]]],
        sink_stats: Mapping[str, Mapping[str, object]],
        *,
        halted: bool,
    ) -> dict[str, int]:
        """Every loss by cause (see the module docstring); ``counters["dropped"]`` is their sum.

        Parameters
        ----------
        source : Source
            Its :meth:`~vpp_service.sources.base.Source.losses` are added as they are.
        input_queue : QueueWorker
            The process stage's queue (``input_queue``: its drops).
        sink_queues : sequence of (str, QueueWorker)
            Each sink's name and queue.
        sink_stats : mapping
            Each sink's ``stats()`` by name (its own ``dropped``).
        halted : bool
            ``max_frames`` was reached: frames left queued or being matched were not wanted.
        """
        with self._lock:
            stop = dict(self._stop_losses)
        out = {
            "input_queue": input_queue.dropped,
            "shutdown": (0 if halted else input_queue.discarded + stop["abandoned"])
            + sum(w.discarded for _, w in sink_queues)
            + stop["refused"]
            + stop["unsent"],
        }
        try:
            out.update({k: int(v) for k, v in source.losses().items()})
        except Exception:  # a source's broken counters must not break @status
            log.debug("source.losses() failed", exc_info=True)
        for name, worker in sink_queues:
            n = sink_stats.get(name, {}).get("dropped", 0)  # the sink's own losses (a viewer gone, ...)
            out[f"sink.{name}"] = (n if isinstance(n, int) else 0) + worker.dropped  # + its full queue's
        return out

    def metrics(self) -> MetricsStatus:
        """The accuracy figures (see :class:`MetricsStatus`)."""
        return {
            "last": self._last_metrics,
            "bad2_answered_mean": _mean(self._bad2_answered),
            "density_mean": _mean(self._density),
            "bad2_filled_mean": _mean(self._bad2_filled),
        }

    def fps(self, elapsed: float) -> float:
        """Frames processed per second over the last :data:`FPS_WINDOW_S` (0 when input stopped that long ago).

        ``elapsed`` is the time since the pipeline started (the window is never longer).
        """
        span = min(FPS_WINDOW_S, elapsed)
        if span <= 0:
            return 0.0
        cutoff = time.monotonic() - span
        recent = sum(1 for t in list(self._done_at) if t >= cutoff)
        return recent / span


def queue_status(worker: QueueWorker[Any]) -> QueueStatus:
    """Fill and drops of ``worker``'s queue."""
    return {
        "len": len(worker),
        "size": worker.size,
        "policy": worker.policy,
        "dropped": worker.dropped,
        "high_water": worker.high_water,
    }


def window_status(window: InFlight[Any, Any] | None, size: int) -> dict[str, QueueStatus]:
    """The frames in flight as a queue, ``{"in_flight": ...}`` (``{}`` for one frame at a time, ``size`` 1)."""
    if size == 1:
        return {}
    return {
        "in_flight": {
            "len": 0 if window is None else window.outstanding,
            "size": size,
            "policy": "block",
            "dropped": 0,
            "high_water": 0 if window is None else window.high_water,
        }
    }


def session_links(session: zenoh.Session | None) -> dict[str, int] | None:
    """Routers and peers ``session`` reaches now (None without a session, or while it closes)."""
    if session is None:
        return None
    try:
        info = session.info
        return {"routers": len(list(info.routers_zid())), "peers": len(list(info.peers_zid()))}
    except Exception:  # noqa: BLE001 - a closing session must not break @status
        return None


class StatusReplies:
    """The ``@status`` replies: one JSON snapshot per :data:`STATUS_SNAPSHOT_S`, shared by the queries meanwhile.

    A query flood costs a lookup per query, not a status build each (counted as ``cached``).

    Parameters
    ----------
    build : callable
        ``build() -> PipelineStatus``, the status now.
    """

    def __init__(self, build: Callable[[], PipelineStatus]) -> None:
        self._build = build
        self._lock = threading.Lock()
        self._snapshot: tuple[float, str] | None = None  # (monotonic time, JSON) of the last reply built
        self._counts = {"queries": 0, "snapshots": 0, "cached": 0}
        self._key = ""
        self._queryable: zenoh.Queryable[None] | None = None
        self._token: zenoh.LivelinessToken | None = None

    def reply(self) -> str:
        """The JSON to reply to one ``@status`` query with."""
        with self._lock:
            self._counts["queries"] += 1
            now = time.monotonic()
            if self._snapshot is None or now - self._snapshot[0] >= STATUS_SNAPSHOT_S:
                self._counts["snapshots"] += 1
                self._snapshot = (now, json.dumps(self._build()))
            else:
                self._counts["cached"] += 1
            return self._snapshot[1]

    def counts(self) -> dict[str, int]:
        """``queries`` replied to, ``snapshots`` built, ``cached`` (replied to from a snapshot)."""
        # not under the lock: the status is built inside it when a query builds a snapshot
        return dict(self._counts)

    def serve(self, session: zenoh.Session, key: str, alive_key: str) -> None:
        """Answer ``@status`` queries on ``key`` and hold the liveliness token ``alive_key`` on ``session``."""
        self._key = key
        self._queryable = session.declare_queryable(key, self._on_query)
        self._token = session.liveliness().declare_token(alive_key)

    def _on_query(self, query: zenoh.Query) -> None:
        # runs on a Zenoh thread: reply with the cached snapshot, never block
        try:
            # the service's own key, not the query's: a wildcard query gets one entry per rig
            query.reply(self._key, self.reply())
        except Exception as exc:  # noqa: BLE001 - session closing; nothing may raise into Zenoh's thread
            log.debug("@status reply failed: %s", exc)

    def withdraw(self) -> None:
        """Stop answering and drop the token (nothing to do when :meth:`serve` was not called)."""
        for obj in (self._queryable, self._token):
            if obj is not None:
                # undeclaring fails only when the session is already closed, which undeclared it anyway
                with contextlib.suppress(Exception):
                    obj.undeclare()
        self._queryable, self._token = None, None


def summary_line(status: PipelineStatus, waits_on: Callable[[], str] | None = None) -> str:
    """One-line live summary of ``status``: fps, latency p50/p99, bad-2 vs GT when known, counters.

    ``waits_on`` says what a running pipeline takes frames from: while nothing has been received the
    line says that instead (None: stopped, the counters are shown).
    """
    c = status["counters"]
    if c["received"] == 0 and waits_on is not None:  # running, nothing yet (the final line has counters)
        return f"waiting for frames on {waits_on()}: nothing has arrived yet"
    lat = status["timing_ms"].get("latency")
    lat_s = f"lat p50 {lat['p50']:.0f} ms p99 {lat['p99']:.0f} ms" if lat else "lat -"
    m = status["metrics"]
    bad_s = ""
    if m["density_mean"] is not None:
        # two numbers, never mixed: accuracy of the values given, and how many pixels got one
        bad2, filled = m["bad2_answered_mean"], m["bad2_filled_mean"]
        bad_s = (" | bad-2 -" if bad2 is None else f" | bad-2 {bad2:.2f} % of answered") + (
            f", density {m['density_mean']:.1f} %" + ("" if filled is None else f", filled {filled:.2f} %")
        )
    throttled = sum(n for s in status["sinks"].values() if isinstance(n := s.get("throttled"), int))
    thr_s = f" throttled {throttled}" if throttled else ""  # skipped on purpose (a viewer's max_hz), not lost
    return (
        f"{status['fps']:.1f} fps | {lat_s}{bad_s} | recv {c['received']} proc {c['processed']} "
        f"pub {c['published']} drop {c['dropped']} rej {c['rejected']} no-depth {c['no_depth']}{thr_s}"
    )


def _mean(values: deque[float]) -> float | None:
    """Mean of a window, None when empty."""
    return float(np.mean(values)) if values else None


__all__ = [
    "COUNTER_NAMES",
    "FPS_WINDOW_S",
    "STATUS_SNAPSHOT_S",
    "Ledger",
    "MetricsStatus",
    "PipelineStatus",
    "QueueStatus",
    "StatusReplies",
    "StopLoss",
    "queue_status",
    "summary_line",
]
