"""The streaming pipeline: source -> process -> sink fan-out, in threads.

::

    network --> [source's receive rings] --> source thread --emit--> [input queue] --> process thread
                (Zenoh, ROS 2 only)                                                     (Fusion)
        --> [queue of sink 1] --> sink 1's thread (sink.write)
        --> [queue of sink 2] --> sink 2's thread ...

The pipeline owns every buffer after the source: the input queue, and one queue
and thread per sink (:class:`~vpp_service.service.fan_out.FanOut`: a slow sink
delays only itself). Each is a :class:`~vpp_service.queueing.QueueWorker` (a
bounded queue and its thread) with a policy: ``latest`` drops the oldest item when
full (a live camera: the freshest frame wins, drops are counted) or ``block``
(lossless: the producer waits; always for a sink that must never drop, such as a
recording). When the source has finished, the process stage handles what is queued
and finishes the sink threads; the last one to exit sets :attr:`Pipeline.done`. A
result is ``published`` once every sink has handled it (none dropped it). What became
of every frame (counters, losses by cause, timings, accuracy) is kept by the pipeline's
:class:`~vpp_service.service.ledger.Ledger` and reported by :meth:`Pipeline.status`,
which the service also serves as JSON on the ``<prefix>/<rig>/@status`` queryable; a
liveliness token ``<prefix>/<rig>/@alive`` is held while the pipeline runs. Under the
``block`` input policy the source is asked to back-pressure its producer instead of dropping.

A source whose thread dies on an exception ends the pipeline like an exhausted
one, but ``status()["source_error"]`` names the exception (the service exits 1).

Bad input never stops the pipeline: a rejected message is counted and logged (at most once per
``reject_log_period_s``); a frame the process step raises on is counted as rejected and dropped.
One exception: a frame the configured disparity range cannot fit
(:class:`~vpp_service.matchers.DisparityRangeError`) stops the pipeline like an exhausted source,
``status()["config_error"]`` saying why (the service exits 2); from a network source, where any
peer may send any size, it is rejected like other bad input, one error line per size.
``max_frames`` counts rejected frames with the processed ones. Each frame is stamped when
received (``meta["recv_ns"]``, :func:`time.monotonic_ns`), never trusting the sender's
``stamp_ns``. A frame whose ``rig`` is not the rig the pipeline serves is rejected before it
is queued, so sinks never see a foreign or forged rig name.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING

from vpp_service.frame import FusionResult, StereoFrame
from vpp_service.matchers.base import DisparityRangeError
from vpp_service.queueing import Policy, QueueWorker
from vpp_service.service.fan_out import FanOut, close_within
from vpp_service.service.in_flight import InFlight
from vpp_service.service.ledger import (
    Ledger,
    PipelineStatus,
    StatusReplies,
    queue_status,
    session_links,
    summary_line,
    window_status,
)

if TYPE_CHECKING:  # zenoh, sources and sinks are imported where they are used
    import zenoh

    from vpp_service.sinks.base import Sink
    from vpp_service.sources.base import Source

log = logging.getLogger(__name__)


class Pipeline:
    """Threaded source -> process -> sinks pipeline (see the module docstring).

    Parameters
    ----------
    source : Source
        Built (not opened) source.
    process : callable
        ``process(frame) -> FusionResult`` (normally :class:`~vpp_service.fusion.Fusion`).
    sinks : sequence of Sink
        Built (not opened) sinks.
    input_size, output_size : int
        Queue capacities.
    input_policy, output_policy : {"latest", "block"}
        Queue policies.
    max_frames : int
        Stop after this many frames processed or rejected (0 = no limit): a
        source whose every frame is rejected still ends.
    session : zenoh.Session or None
        When given, ``@status`` and ``@alive`` are declared on it.
    prefix, rig : str
        Key prefix and rig name for ``@status`` / ``@alive``.
    timing_window : int
        Window of the timing statistics.
    reject_log_period_s : float
        Rate limit of the rejected-input log line.
    in_flight : int
        Frames processed at once (:class:`~vpp_service.service.in_flight.InFlight`; a network on
        remote servers): results still leave in the order the frames came, and the process stage
        waits while the window is full. 1 (default): one frame at a time on the process thread.
    """

    def __init__(
        self,
        source: Source,
        process: Callable[[StereoFrame], FusionResult],
        sinks: Sequence[Sink] = (),
        *,
        input_size: int = 2,
        input_policy: Policy = "latest",
        output_size: int = 4,
        output_policy: Policy = "latest",
        max_frames: int = 0,
        session: zenoh.Session | None = None,
        prefix: str = "vpp",
        rig: str = "rig0",
        timing_window: int = 200,
        reject_log_period_s: float = 5.0,
        in_flight: int = 1,
    ) -> None:
        if not callable(process):
            raise TypeError("process must be callable")
        if max_frames < 0:
            raise ValueError(f"max_frames must be >= 0, got {max_frames}")
        self.source = source
        source.input_policy = input_policy  # "block": the source back-pressures its producer too
        self.process = process
        self.sinks = list(sinks)
        self.input: QueueWorker[StereoFrame] = QueueWorker(
            self._process,
            size=input_size,
            policy=input_policy,
            name="pipeline-process",
            on_exit=self._process_done,
            on_error=self._process_failed,
        )
        self.max_frames = max_frames
        self.session = session
        self.prefix, self.rig = prefix, rig
        #: What became of every frame: counters, losses by cause, timings, accuracy (the status's figures).
        self.ledger = Ledger(timing_window, reject_log_period_s)
        self._stop = threading.Event()
        self.done = threading.Event()
        #: One queue and thread per sink, from its spec (the pipeline owns every buffer on the way out).
        self.fan_out = FanOut(
            self.sinks,
            size=output_size,
            policy=output_policy,
            ledger=self.ledger,
            stopping=self._stop,
            on_done=self.done.set,
        )
        #: Why the pipeline stopped on its own (a frame the disparity range cannot fit; the service exits 2).
        self.config_error: str | None = None
        self._range_misfits: set[tuple[int, int]] = set()  # frame sizes a network frame's range misfit was logged for
        if isinstance(in_flight, bool) or not isinstance(in_flight, int) or in_flight < 1:
            raise ValueError(f"in_flight must be an integer >= 1, got {in_flight!r}")
        self.in_flight = in_flight
        self._window: InFlight[StereoFrame, FusionResult] | None = None
        self._lock = threading.Lock()
        self._enough = threading.Event()
        self._started = 0.0
        self._opened: list[Sink] = []
        self._matching = 0  # frames in the process step now (in_flight == 1: 0 or 1)
        self._abandoned = False  # a stop gave up on the frames still being matched
        #: Sinks whose close raised or did not return within the shutdown timeout (their output may be incomplete).
        self.unfinished_sinks: list[str] = []
        self._replies = StatusReplies(self.status)  # @status and @alive: the replies, one snapshot per period
        #: What runs the matcher (the process step's ``runtime()``, taken at :meth:`start`; None without one).
        self.matcher_runtime: dict[str, object] | None = None

    # ----------------------------------------------------------- counters
    @property
    def counters(self) -> dict[str, int]:
        """A snapshot of the counters; ``dropped`` is the sum of every loss by cause (:meth:`status`)."""
        return self.status()["counters"]

    @property
    def rejected(self) -> int:
        """``counters["rejected"]`` without building the whole :meth:`status` (cheap enough to poll)."""
        return self.ledger.get("rejected")

    def _emit(self, frame: StereoFrame) -> bool:
        self.ledger.count("received")
        if frame.rig != self.rig:  # the rig comes from the message: only the served rig's frames go on
            self._reject(f"frame seq={frame.seq}: rig {frame.rig[:64]!r} is not the served rig {self.rig!r}")
            return False
        frame.meta.setdefault("recv_ns", time.monotonic_ns())  # sources that receive stamp it earlier
        return self._enqueue(frame)

    def _enqueue(self, frame: StereoFrame) -> bool:
        """Queue ``frame`` for processing (the input policy decides how); whether it was queued."""
        ok = False
        if self.input.policy == "block":
            while not (self._stop.is_set() or self._enough.is_set()):
                if self.input.put(frame, timeout=0.1):
                    ok = True
                    break
        elif not (self._stop.is_set() or self._enough.is_set()):
            ok = self.input.put(frame)
        if not ok and not self._enough.is_set():  # after max_frames, input is unwanted, not lost
            self.ledger.lost_at_stop("refused")
        return ok

    def _source_reject(self, reason: str) -> None:
        self.ledger.count("received")
        self._reject(reason)

    def _reject(self, reason: str) -> None:
        """Count and log (rate-limited) one rejected message; it counts towards ``max_frames``."""
        self.ledger.reject(reason)
        self._count_towards_limit()

    # -------------------------------------------------------------- stages
    def _process(self, frame: StereoFrame) -> None:
        """Process stage (its worker thread): one frame through ``process``, the result to the sinks.

        With ``in_flight`` > 1 the frame joins the window (waiting for a free slot) and its result is
        handed on by the window's delivering thread, in order.
        """
        if self._enough.is_set():
            return
        if self._window is not None:
            if not self._window.submit(frame, self._stop):
                self.ledger.lost_at_stop("refused")  # stopping while the window was full: counted as shutdown
            return
        with self._lock:
            abandoned = self._abandoned
            self._matching += 0 if abandoned else 1
        if abandoned:  # taken from the queue just before a stop gave up: never matched
            self.ledger.lost_at_stop("refused")
            return
        try:
            result = self.process(frame)
        except Exception:
            if self._settled():
                raise  # the input stage's on_error: _process_failed
            return
        if self._settled():
            self._processed(result)

    def _settled(self) -> bool:
        """The process step returned (in_flight 1): True to hand its outcome on, False when a stop counted it lost."""
        with self._lock:
            self._matching -= 1
            return not self._abandoned

    def _abandon(self) -> None:
        """A stop that cannot wait: the frames still being matched are lost (counted under ``shutdown``)."""
        with self._lock:
            self._abandoned = True
            lost = self._matching
        if self._window is not None:
            lost += self._window.abandon()
        self.ledger.lost_at_stop("abandoned", lost)
        if lost:
            log.warning("stopping: %d frame(s) still being matched are abandoned (counted as shutdown)", lost)

    def _processed(self, result: FusionResult) -> None:
        """A frame's result: into the ledger (timings, accuracy, counters), then to the sinks."""
        if self._enough.is_set():
            return  # max_frames reached while it was in flight: unwanted, not lost
        self.ledger.processed(result)
        self.fan_out.deliver(result)
        prepare = getattr(self.process, "prepare_next", None)
        if prepare is not None:
            try:
                prepare(result.frame)  # optional idle-time work for the next frame
            except Exception as exc:  # noqa: BLE001 - optional idle-time work: a failure only costs the head start
                log.debug("prepare_next(seq=%s): %r", result.frame.seq, exc)
        self._count_towards_limit()

    def _count_towards_limit(self) -> None:
        """After a frame was processed or rejected: stop taking input once ``max_frames`` of them were."""
        if self.max_frames and self.ledger.handled() >= self.max_frames:
            self._halt()

    def _halt(self) -> None:
        """Take no more input: the source stops, frames still queued are not processed (not counted as lost)."""
        self._enough.set()
        self.source.request_stop()  # no more input wanted
        self.input.abort()

    def _process_failed(self, frame: StereoFrame, exc: Exception) -> None:
        """A frame ``process`` raised on: a ValueError rejects it, anything else is counted as an error.

        A :class:`~vpp_service.matchers.DisparityRangeError` (the configured disparity range
        cannot fit a frame this wide) stops the pipeline: every such frame would fail alike. From a
        network source (any peer can send a frame of any size) it only rejects the frame, with one
        error line per frame size, and the service keeps serving the frames that fit.
        """
        if isinstance(exc, DisparityRangeError):
            h, w = frame.shape
            why = f'frame seq={frame.seq} is {w} x {h}: {exc}; set a smaller matcher.max_disparity, or "auto"'
            if self.source.network:
                if (h, w) not in self._range_misfits and len(self._range_misfits) < 16:  # bounded: hostile peers
                    self._range_misfits.add((h, w))
                    log.error("rejecting every %d x %d frame: %s", w, h, why)
                self._reject(why)
                return
            self.ledger.count("rejected")
            if self.config_error is None:
                self.config_error = why
                log.info("stopping: %s", self.config_error)
            self._halt()
            return
        if isinstance(exc, ValueError):  # a frame the matcher/VPP cannot take (size, range)
            self._reject(f"frame seq={frame.seq}: {exc}")
            return
        self.ledger.failed(frame.seq, exc)  # never let one frame kill the service

    def _process_done(self) -> None:
        """The process stage ended: the sink threads finish what is queued (or ``done`` now, without sinks)."""
        if self._window is not None:
            self._window.close()  # the frames in flight get their results, handed on first
        self.fan_out.finish()

    # ----------------------------------------------------------- lifecycle
    def start(self) -> None:
        """Open sinks and source, declare ``@status``/``@alive``, start the threads.

        Raises
        ------
        Exception
            Whatever a sink's or the source's ``open`` raises (already opened
            parts are closed again).
        """
        runtime = getattr(self.process, "runtime", None)  # a network's engine opens here, before any frame
        self.matcher_runtime = dict(runtime()) if callable(runtime) else None
        try:
            for sink in self.sinks:
                sink.open()
                self._opened.append(sink)
            self.source.open()
        except BaseException:
            for sink in self._opened:
                sink.close(1.0)
            raise
        if self.session is not None:
            from vpp_service.transport.wire import topic

            at = (self.prefix, self.rig)
            self._replies.serve(self.session, topic(*at, "@status"), topic(*at, "@alive"))
        self._started = time.monotonic()
        if self.in_flight > 1:
            self._window = InFlight(
                self.in_flight, self.process, self._processed, self._process_failed, name="pipeline-match"
            )
        self.fan_out.start()
        self.input.start()
        self.source.start(self._emit, self._source_reject, on_finished=self.input.finish)

    def wait(self, timeout: float | None = None) -> bool:
        """Block until the pipeline is done (source exhausted / max_frames) or ``timeout``."""
        return self.done.wait(timeout)

    def stop(self, timeout: float = 5.0) -> None:
        """Stop the source, drain the queues, close sinks; every step bounded by ``timeout``."""
        self.source.stop(timeout)
        self.source.finished.set()
        deadline = time.monotonic() + timeout
        self.input.finish()
        drained = self.input.join(max(0.05, deadline - time.monotonic()))
        drained = self.fan_out.join(deadline) and drained
        if not drained:
            log.warning("pipeline threads did not drain within %.1f s; abandoning the queued results", timeout)
            self._stop.set()
            self.input.abort()
            self._abandon()
            self.input.join(1.0)
            self.fan_out.abort()
        self._stop.set()
        for sink in self._opened:
            if not close_within(sink, timeout):
                self.unfinished_sinks.append(type(sink).__name__)
        self._replies.withdraw()
        self.done.set()

    # -------------------------------------------------------------- status
    def status(self) -> PipelineStatus:
        """Counters, losses by cause, queue fill, timings, source and sink stats (JSON-ready; the ledger's figures).

        With what runs the matcher (``matcher``: engine, device, precision, threads, the range in use)
        when the process step says, and a network's requests and servers (``network``) when it has them.
        """
        counters = self.ledger.counts()
        elapsed = time.monotonic() - self._started if self._started else 0.0
        sinks: dict[str, Mapping[str, object]] = {}
        for s in self.sinks:
            try:
                sinks[type(s).__name__] = s.stats()
            except Exception:  # noqa: BLE001 - a sink's broken counters must not break @status
                sinks[type(s).__name__] = {}
        sink_queues = self.fan_out.queues()
        dropped = self.ledger.losses(self.source, self.input, sink_queues, sinks, halted=self._enough.is_set())
        counters["dropped"] = sum(dropped.values())  # derived: every cause in one count
        status: PipelineStatus = {
            "rig": self.rig,
            "prefix": self.prefix,
            "uptime_s": elapsed,
            "counters": counters,
            "dropped": dropped,
            "source_error": None if self.source.error is None else repr(self.source.error),
            "config_error": self.config_error,
            "zenoh": self.connectivity(),
            "fps": self.ledger.fps(elapsed),
            "queues": {
                "input": queue_status(self.input),
                **{f"sink.{name}": queue_status(w) for name, w in sink_queues},
                **window_status(self._window, self.in_flight),
            },
            "timing_ms": self.ledger.timer.summary(),
            "status_queries": self._replies.counts(),
            "source": self.source.stats(),
            "sinks": sinks,
            "metrics": self.ledger.metrics(),
        }
        if self.matcher_runtime is not None:
            status["matcher"] = self._matcher_status()
        network = getattr(self.process, "network_status", None)
        if callable(network):
            net = network()
            if net:  # a network on remote servers: requests, retries, bad replies, each server's state
                status["network"] = net
        return status

    def _matcher_status(self) -> dict[str, object]:
        """:attr:`matcher_runtime` as it is now (the ``auto`` range changes); the start's when it cannot be read."""
        runtime = getattr(self.process, "runtime", None)
        try:
            return dict(runtime()) if callable(runtime) else dict(self.matcher_runtime or {})
        except Exception:  # a matcher's broken report must not break @status
            log.debug("runtime() failed", exc_info=True)
            return dict(self.matcher_runtime or {})

    def connectivity(self) -> dict[str, int] | None:
        """Routers and peers the session reaches now (None without a session)."""
        return session_links(self.session)

    def summary_line(self, status: PipelineStatus | None = None) -> str:
        """One-line live summary (:func:`~vpp_service.service.ledger.summary_line`).

        ``status`` is a :meth:`status` the caller already has (None: taken now).
        """
        st = self.status() if status is None else status
        return summary_line(st, None if self._stop.is_set() else self.source.waits_on)


__all__ = ["Pipeline"]
