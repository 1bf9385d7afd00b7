"""The pipeline's ledger: counters, losses by cause, the rate-limited reject log, the ``@status`` figures."""

from __future__ import annotations

import json
import logging
import threading
import time

import numpy as np
import pytest

from helpers.sinks import CollectSink
from vpp_service.frame import FusionResult, StereoFrame
from vpp_service.metrics import answered_metrics, compute_metrics
from vpp_service.queueing import QueueWorker
from vpp_service.service.ledger import (
    COUNTER_NAMES,
    STATUS_SNAPSHOT_S,
    Ledger,
    PipelineStatus,
    StatusReplies,
    queue_status,
    summary_line,
)
from vpp_service.service.pipeline import Pipeline
from vpp_service.sources.base import Source, SourceContext

FRAME = StereoFrame(np.zeros((4, 6, 3), np.uint8), np.zeros((4, 6, 3), np.uint8), rig="rig0")


def result(frame: StereoFrame = FRAME, **kw) -> FusionResult:
    return FusionResult(frame=frame, disparity=np.zeros(frame.shape, np.float32), **kw)


class ListSource(Source):
    """Emits the given frames, then is exhausted."""

    Options = None

    def __init__(self, frames: list[StereoFrame]) -> None:
        super().__init__(None, SourceContext(rig="rig0"))
        self.frames = frames

    def run(self, emit, reject):
        for f in self.frames:
            if self.stopping():
                return
            emit(f)


# ------------------------------------------------------------------ counting
def test_counts_processed_published_and_the_accuracy_windows():
    gt = np.full((10, 20), 10.0, np.float32)
    disp = gt.copy()
    disp[:, :5] = np.nan  # a quarter of the pixels without a value
    disp[:2, 5:] += 5.0  # 30 of the 150 answered pixels off by 5 px
    metrics = {**compute_metrics(disp, gt), "bad2_filled": 42.0}
    ledger = Ledger(timing_window=10)
    frame = FRAME.with_(sparse_disparity=np.zeros((4, 6), np.float32), meta={"recv_ns": time.monotonic_ns()})
    ledger.processed(result(frame, metrics=metrics, timing_ms={"match": 3.0}, see_through=7))
    ledger.processed(result())  # no sparse points, no ground truth
    ledger.published(result(frame))
    c = ledger.counts()
    assert set(c) == set(COUNTER_NAMES)
    assert (c["processed"], c["published"], c["no_depth"], c["sparse.see_through"]) == (2, 1, 1, 7)
    assert ledger.handled() == 2 and ledger.get("rejected") == 0
    m = ledger.metrics()
    split = answered_metrics(metrics)
    assert m["density_mean"] == pytest.approx(75.0) == split["density"]
    assert m["bad2_answered_mean"] == pytest.approx(20.0) == split["bad2_answered"]
    assert m["bad2_filled_mean"] == 42.0 and m["last"]["bad2_answered"] == split["bad2_answered"]
    timing = ledger.timer.summary()
    assert timing["match"]["n"] == 1 and 0 <= timing["latency"]["last"] < 10_000
    assert ledger.fps(elapsed=10.0) == pytest.approx(2 / 5.0)  # two frames in the 5 s window
    assert ledger.fps(elapsed=0.0) == 0.0


def test_a_ledger_without_ground_truth_reports_no_accuracy():
    m = Ledger().metrics()
    assert m == {"last": {}, "bad2_answered_mean": None, "density_mean": None, "bad2_filled_mean": None}


def test_unknown_counter_and_bad_settings_are_refused_naming_them():
    ledger = Ledger()
    with pytest.raises(KeyError, match=r"unknown counter 'recieved'.*received, rejected"):
        ledger.count("recieved")
    with pytest.raises(ValueError, match="log_period_s must be >= 0, got -1"):
        Ledger(log_period_s=-1)
    with pytest.raises(ValueError, match="window must be >= 1"):
        Ledger(timing_window=0)
    assert ledger.counts() == dict.fromkeys(COUNTER_NAMES, 0)  # the refused count left no trace


def test_the_reject_log_is_rate_limited_and_says_how_many_it_held_back(caplog):
    ledger = Ledger(log_period_s=0.3)
    with caplog.at_level(logging.WARNING, logger="vpp_service.service.ledger"):
        for i in range(5):
            ledger.reject(f"bad message {i}")
        time.sleep(0.35)
        ledger.reject("bad message 5")
    lines = [r.getMessage() for r in caplog.records]
    assert lines == ["rejected input: bad message 0", "rejected input: bad message 5 (+4 more since the last report)"]
    assert ledger.get("rejected") == 6


def test_failed_frames_are_counted_each_and_logged_once_per_period(caplog):
    ledger = Ledger(log_period_s=60.0)
    with caplog.at_level(logging.ERROR, logger="vpp_service.service.ledger"):
        for seq in range(3):
            ledger.failed(seq, RuntimeError("boom"))
    assert ledger.get("errors") == 3
    assert [r.getMessage() for r in caplog.records] == ["processing frame seq=0 failed: RuntimeError('boom')"]


def test_counting_from_many_threads_loses_no_count():
    ledger = Ledger(log_period_s=3600)

    def work() -> None:
        for _ in range(2000):
            ledger.count("received")
            ledger.reject("x")

    threads = [threading.Thread(target=work) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert ledger.get("received") == ledger.get("rejected") == 8000


# -------------------------------------------------------------------- losses
class LossySource(Source):
    Options = None

    def run(self, emit, reject):  # never started
        raise AssertionError("not run")

    def losses(self) -> dict[str, int]:
        return {"source_ring": 3, "sync": 2}


class BrokenSource(LossySource):
    def losses(self) -> dict[str, int]:
        raise RuntimeError("broken counters")


@pytest.mark.parametrize("halted", [False, True])
def test_losses_name_every_cause_and_a_halt_wants_nothing_queued(halted):
    """Drops of a full queue, a stop's discards and losses, the source's and each sink's own, by cause."""
    input_queue: QueueWorker[int] = QueueWorker(lambda x: None, size=1, policy="latest")
    sink_queue: QueueWorker[int] = QueueWorker(lambda x: None, size=2, policy="latest")
    for i in range(4):
        input_queue.put(i)  # 3 dropped, 1 queued
        sink_queue.put(i)  # 2 dropped, 2 queued
    input_queue.abort()  # 1 discarded
    sink_queue.abort()  # 2 discarded
    ledger = Ledger()
    ledger.lost_at_stop("refused")
    ledger.lost_at_stop("abandoned", 4)
    ledger.lost_at_stop("unsent", 2)
    d = ledger.losses(
        LossySource(None, SourceContext()),
        input_queue,
        [("Out", sink_queue)],
        {"Out": {"dropped": 5}},
        halted=halted,
    )
    # a halt (max_frames reached): the input still queued and the frames being matched were unwanted
    shutdown = (0 if halted else 1 + 4) + 2 + 1 + 2
    assert d == {"input_queue": 3, "shutdown": shutdown, "source_ring": 3, "sync": 2, "sink.Out": 5 + 2}
    broken = ledger.losses(BrokenSource(None, SourceContext()), input_queue, [], {}, halted=halted)
    assert set(broken) == {"input_queue", "shutdown"}  # a source's broken counters do not break the status
    assert queue_status(sink_queue) == {"len": 0, "size": 2, "policy": "latest", "dropped": 2, "high_water": 2}


# --------------------------------------------------------------- the figures
def test_status_replies_share_one_snapshot_per_period():
    built = []

    def build() -> PipelineStatus:
        built.append(time.monotonic())
        return {"rig": "r", "n": len(built)}  # type: ignore[typeddict-item]

    replies = StatusReplies(build)
    first, second = replies.reply(), replies.reply()
    assert first == second == json.dumps({"rig": "r", "n": 1})
    time.sleep(STATUS_SNAPSHOT_S + 0.02)
    assert json.loads(replies.reply())["n"] == 2
    assert replies.counts() == {"queries": 3, "snapshots": 2, "cached": 1}


def test_summary_line_waits_then_reports_the_figures():
    ledger = Ledger()
    status = {
        "counters": {**ledger.counts(), "dropped": 0},
        "timing_ms": {},
        "metrics": ledger.metrics(),
        "sinks": {"Viewer": {"throttled": 3}},
        "fps": 0.0,
    }
    waiting = summary_line(status, lambda: "vpp/r/in/frame")  # type: ignore[arg-type]
    assert waiting == "waiting for frames on vpp/r/in/frame: nothing has arrived yet"
    ledger.count("received", 2)
    ledger.processed(result())
    status["counters"] = {**ledger.counts(), "dropped": 1}
    line = summary_line(status, lambda: "unused")  # type: ignore[arg-type]
    assert line == "0.0 fps | lat - | recv 2 proc 1 pub 0 drop 1 rej 0 no-depth 1 throttled 3"


# ---------------------------------------------------- the accounting identity
class Picky:
    """A process step: ValueError (rejected) on every 5th frame, RuntimeError (an error) on every 7th."""

    def __init__(self, delay: float) -> None:
        self.delay = delay

    def __call__(self, frame: StereoFrame) -> FusionResult:
        time.sleep(self.delay)
        if frame.seq % 5 == 1:
            raise ValueError("a frame the matcher cannot take")
        if frame.seq % 7 == 3:
            raise RuntimeError("a matcher failure")
        return result(frame)


@pytest.mark.parametrize(("policy", "in_flight"), [("latest", 1), ("block", 1), ("latest", 3), ("block", 3)], ids=str)
def test_every_received_frame_ends_in_exactly_one_count(policy, in_flight):
    """Every frame is rejected, processed, an error, or lost (input_queue, shutdown); each processed one published."""
    n = 60
    frames = [FRAME.with_(seq=i, rig="rig1" if i % 11 == 4 else "rig0") for i in range(n)]  # 5 of a foreign rig
    sink = CollectSink()
    pipe = Pipeline(
        ListSource(frames), Picky(0.002), [sink], input_size=1, input_policy=policy, output_policy="block",
        in_flight=in_flight,
    )  # fmt: skip
    pipe.start()
    assert pipe.wait(30), "pipeline did not finish"
    pipe.stop(5.0)
    st = pipe.status()
    c, d = st["counters"], st["dropped"]
    assert c["received"] == n
    assert c["rejected"] + c["processed"] + c["errors"] + d["input_queue"] + d["shutdown"] == n
    assert c["published"] == c["processed"] == len(sink.results) and d["sink.CollectSink"] == 0
    assert c["dropped"] == sum(d.values())
    if policy == "block":  # nothing lost: each frame's fate is known from its seq
        seqs = range(n)
        foreign = {i for i in seqs if i % 11 == 4}
        value_error = {i for i in seqs if i % 5 == 1} - foreign
        runtime_error = {i for i in seqs if i % 7 == 3} - foreign - value_error
        assert (c["rejected"], c["errors"], d["input_queue"], d["shutdown"]) == (
            len(foreign) + len(value_error), len(runtime_error), 0, 0
        )  # fmt: skip
        assert [r.frame.seq for r in sink.results] == sorted(set(seqs) - foreign - value_error - runtime_error)
    else:
        assert d["input_queue"] > 0  # the test exercised the drops it counts
