"""Pipeline: queue policies under a fast source and slow processing, counters, timings, errors."""

from __future__ import annotations

import json
import threading
import time

import numpy as np
import pytest
import zenoh

from helpers.frames import make_frame
from helpers.sinks import CollectSink
from helpers.zenoh_loopback import zenoh_test_config
from vpp_service.frame import FusionResult, StereoFrame
from vpp_service.fusion import Fusion, score
from vpp_service.matchers import fill_holes
from vpp_service.metrics import answered_metrics, compute_metrics
from vpp_service.service.pipeline import Pipeline
from vpp_service.sinks.base import QueueSpec
from vpp_service.sources.base import Source, SourceContext, build_source
from vpp_service.timing import StageTimer
from vpp_service.transport import wire


class SlowProcess:
    """Processing step that takes ``delay`` s and tracks the input-queue length it sees."""

    def __init__(self, pipe_ref: list, delay: float = 0.02) -> None:
        self.delay, self.pipe_ref, self.max_len = delay, pipe_ref, 0

    def __call__(self, frame):
        self.max_len = max(self.max_len, len(self.pipe_ref[0].input))
        time.sleep(self.delay)
        return FusionResult(frame=frame, disparity=np.zeros(frame.shape, np.float32), timing_ms={"match": 1.0})


def sim_source(count: int, rate_hz: float = 0.0, sensor: str = "none"):
    return build_source(
        "sim",
        {
            "scene": "synthetic",
            "scene_options": {"height": 48, "width": 96, "max_disparity": 16},
            "sensor": sensor,
            "sensor_options": {},
            "count": count,
            "rate_hz": rate_hz,
        },
        SourceContext(rig="rig0"),  # the rig the Pipeline serves by default
    )


def run(pipe: Pipeline, timeout: float = 20.0) -> None:
    pipe.start()
    assert pipe.wait(timeout), "pipeline did not finish"
    pipe.stop(2.0)


def test_stage_timer_matches_numpy():
    t = StageTimer(window=5)
    vals = [5.0, 1.0, 3.0, 9.0, 2.0, 4.0, 8.0]
    for v in vals:
        t.add("x", v)
    s = t.summary()["x"]
    w = np.array(vals[-5:])
    assert s["n"] == 5 and s["last"] == 8.0
    assert s["mean"] == pytest.approx(w.mean()) and s["p99"] == pytest.approx(np.percentile(w, 99))
    assert s["p50"] == np.percentile(w, 50) and s["p99"] == np.percentile(w, 99)  # exactly numpy's
    with pytest.raises(ValueError, match="window must be >= 1"):
        StageTimer(0)


def test_latest_policy_drops_and_stays_bounded():
    ref = []
    proc = SlowProcess(ref, delay=0.02)
    sink = CollectSink()
    pipe = Pipeline(sim_source(60), proc, [sink], input_size=2, input_policy="latest")
    ref.append(pipe)
    run(pipe)
    c = pipe.counters
    assert proc.max_len <= 2 and pipe.input.high_water <= 2
    assert c["received"] == 60
    assert c["dropped"] > 0
    assert c["processed"] + c["dropped"] == 60
    assert c["published"] == c["processed"] == len(sink.results)
    seqs = [r.frame.seq for r in sink.results]
    assert seqs == sorted(seqs) and seqs[-1] == 59  # the freshest frame always gets through
    assert sink.closed


def test_block_policy_loses_nothing():
    ref = []
    proc = SlowProcess(ref, delay=0.005)
    sink = CollectSink()
    pipe = Pipeline(
        sim_source(40), proc, [sink], input_size=2, input_policy="block", output_size=1, output_policy="block"
    )
    ref.append(pipe)
    run(pipe)
    assert [r.frame.seq for r in sink.results] == list(range(40))
    assert pipe.status()["counters"]["dropped"] == 0 and pipe.input.high_water <= 2
    st = pipe.status()
    assert st["counters"]["published"] == 40
    assert st["timing_ms"]["match"]["n"] == 40 and "latency" in st["timing_ms"]


def test_max_frames_stops_early():
    sink = CollectSink()
    pipe = Pipeline(
        sim_source(0, rate_hz=200),
        lambda f: FusionResult(f, np.zeros(f.shape, np.float32)),
        [sink],
        input_policy="block",
        max_frames=5,
    )
    run(pipe)
    assert pipe.counters["processed"] == 5 and len(sink.results) == 5


def test_bad_frames_are_rejected_and_service_keeps_running():
    def process(frame):
        if frame.seq % 3 == 0:
            raise ValueError("bad frame")
        if frame.seq % 5 == 0:
            raise RuntimeError("bug")
        return FusionResult(frame, np.zeros(frame.shape, np.float32))

    sink = CollectSink()
    # both queues block: this test is about rejects and errors, not about the output queue dropping the oldest
    # result when the sink thread is late (it was, on a loaded machine)
    pipe = Pipeline(sim_source(15), process, [sink], input_policy="block", output_policy="block")
    run(pipe)
    c = pipe.counters
    assert c["rejected"] == 5  # 0, 3, 6, 9, 12
    assert pipe.rejected == 5  # the cheap accessor the service polls
    assert c["errors"] == 2  # 5, 10
    assert c["processed"] == len(sink.results) == 8


def test_max_frames_counts_rejected_frames_too():
    """A source whose every frame is rejected still ends at max_frames (rejected + processed)."""

    def process(frame):
        if frame.seq % 2 == 0:
            raise ValueError("bad frame")
        return FusionResult(frame, np.zeros(frame.shape, np.float32))

    sink = CollectSink()
    pipe = Pipeline(sim_source(0, rate_hz=200), process, [sink], input_policy="block", max_frames=6)
    run(pipe)
    c = pipe.counters
    assert (c["rejected"], c["processed"], len(sink.results)) == (3, 3, 3)

    def reject_all(frame):
        raise ValueError("bad frame")

    pipe = Pipeline(sim_source(0, rate_hz=200), reject_all, [], input_policy="block", max_frames=4)
    run(pipe)
    assert (pipe.counters["rejected"], pipe.counters["processed"]) == (4, 0)
    assert pipe.status()["config_error"] is None


def test_a_range_that_cannot_fit_the_frames_stops_the_pipeline_on_the_first_one(caplog):
    """A fixed range not below the frame width fails every frame alike: stop and say why, never loop on rejects."""
    from vpp_service.matchers import build_matcher

    # 96 px wide frames; sgbm rounds 90 up to 96 (OpenCV's multiple of 16), which is not below 96
    fusion = Fusion(build_matcher("sgbm", {"max_disparity": 90}), None, depth=False)
    pipe = Pipeline(sim_source(0, rate_hz=200), fusion, [CollectSink()], input_policy="block")
    with caplog.at_level("WARNING"):
        run(pipe)  # ends by itself on an endless source
    st = pipe.status()
    assert st["counters"]["processed"] == 0 and st["counters"]["rejected"] == 1
    err = st["config_error"]
    assert err is not None and err.startswith("frame seq=0 is 96 x 48: max_disparity 90 (rounded up to 96")
    assert "image width 96" in err and "matcher.max_disparity" in err
    assert not [r for r in caplog.records if "rejected input" in r.getMessage()]  # no reject-log loop either
    # the same range on frames it fits: processed as usual
    fits = Fusion(build_matcher("sgbm", {"max_disparity": 64}), None, depth=False)
    pipe = Pipeline(sim_source(3), fits, [CollectSink()], input_policy="block")
    run(pipe)
    assert pipe.counters["processed"] == 3 and pipe.status()["config_error"] is None


def test_a_network_frame_the_range_cannot_fit_is_rejected_and_the_service_serves_on(caplog):
    """From a network source any peer may send any size: one such frame is a counted reject, never a stop."""
    from vpp_service.matchers import build_matcher

    fusion = Fusion(build_matcher("sgbm", {"max_disparity": 90}), None, depth=False)
    src = sim_source(5)
    src.network = True  # frames as a Zenoh or ROS 2 peer sends them
    pipe = Pipeline(src, fusion, [CollectSink()], input_policy="block")
    with caplog.at_level("ERROR"):
        run(pipe)  # the finite source ends: every frame was taken
    st = pipe.status()
    assert st["config_error"] is None
    assert (st["counters"]["rejected"], st["counters"]["processed"]) == (5, 0)
    said = [r.getMessage() for r in caplog.records if r.levelname == "ERROR"]
    assert len(said) == 1 and said[0].startswith("rejecting every 96 x 48 frame: frame seq=0 is 96 x 48"), said


def test_real_fusion_counts_no_depth_and_scores_against_gt():
    from vpp_service.matchers import build_matcher
    from vpp_service.vpp import VPPConfig

    sink = CollectSink()
    src = sim_source(4, sensor="uniform")
    fusion = Fusion(build_matcher("sgbm", {"max_disparity": 32}), VPPConfig())
    pipe = Pipeline(
        src,
        lambda f: fusion(f if f.seq % 2 else f.with_(sparse_disparity=None, sensor_depth=None)),
        [sink],
        input_policy="block",
    )
    run(pipe)
    assert pipe.counters["no_depth"] == 2 and fusion.counters == {"vpp": 2, "no_depth": 2}
    for r in sink.results:
        assert r.disparity.shape == r.frame.shape and "bad2" in r.metrics
        assert (r.left_vpp is None) == (r.frame.seq % 2 == 0)
        assert r.depth is not None and r.depth.dtype == np.float32


def test_see_through_points_are_counted_in_status():
    from vpp_service.matchers import build_matcher
    from vpp_service.vpp import VPPConfig
    from vpp_service.vpp.see_through import DepthFilter

    sink = CollectSink()
    src = build_source(
        "sim",
        {
            "scene": "synthetic",
            "scene_options": {"height": 48, "width": 96, "max_disparity": 16},
            "sensor": "uniform",
            "sensor_options": {"density": 0.3},
            "count": 3,
            "rate_hz": 0.0,
        },
        SourceContext(rig="rig0"),
    )
    filt = DepthFilter(mode="see-through")
    fusion = Fusion(build_matcher("sgbm", {"max_disparity": 32}), VPPConfig(), depth_filter=filt)
    pipe = Pipeline(src, fusion, [sink], input_policy="block")
    run(pipe)
    counted = [r.see_through for r in sink.results]
    assert len(counted) == 3 and all(n is not None for n in counted)
    assert pipe.status()["counters"]["sparse.see_through"] == sum(counted) > 0


def test_answered_metrics_split_bad2_from_density():
    gt = np.full((10, 20), 10.0, np.float32)
    disp = gt.copy()
    disp[:, :5] = np.nan  # 25 % of the pixels with ground truth get no value
    disp[:3, 5:10] += 5.0  # 15 of the 150 answered pixels are off by more than 2 px
    m = compute_metrics(disp, gt)
    split = answered_metrics(m)
    assert split["density"] == pytest.approx(75.0)
    assert split["bad2_answered"] == pytest.approx(10.0)
    assert m["bad2"] == pytest.approx(32.5)  # the mixed number: 25 % missing + 7.5 % wrong
    assert answered_metrics({"bad2": 1.0}) == {}
    none = answered_metrics(compute_metrics(np.full_like(gt, np.nan), gt))
    assert none["density"] == 0.0 and np.isnan(none["bad2_answered"])


def test_status_and_summary_report_bad2_of_answered_pixels_and_density():
    last_disp, last_gt = [None], [None]

    def process(frame: StereoFrame) -> FusionResult:
        gt = frame.gt_disparity
        disp = gt.copy()
        disp[:, : gt.shape[1] // 4] = np.nan
        disp[::10, gt.shape[1] // 2 :] += 5.0
        last_disp[0], last_gt[0] = disp, gt
        return FusionResult(frame=frame, disparity=disp, metrics=score(disp, frame), timing_ms={"match": 1.0})

    pipe = Pipeline(sim_source(3), process, [CollectSink()], input_policy="block")
    assert pipe.status()["metrics"]["density_mean"] is None and "density" not in pipe.summary_line()
    run(pipe)
    m = pipe.status()["metrics"]
    last = m["last"]
    gt_ok = last["n"]
    assert m["density_mean"] == pytest.approx(last["density"]) and last["density"] == pytest.approx(
        100.0 - last["invalid"]
    )
    assert 70.0 < m["density_mean"] < 80.0
    assert 6.0 < m["bad2_answered_mean"] < 7.5  # every 10th row of 2/3 of the answered columns: 6.7 %
    filled = compute_metrics(fill_holes(last_disp[0]), last_gt[0])["bad2"]  # the eval protocol's score
    assert m["bad2_filled_mean"] == pytest.approx(last["bad2_filled"]) and last["bad2_filled"] == pytest.approx(filled)
    assert last["bad2"] > m["bad2_answered_mean"] + 20.0  # the raw score counts the holes as bad: not reported
    assert gt_ok > 0
    assert "density" in pipe.summary_line()
    st = pipe.status()
    st["fps"] = 1234.5  # a status the caller already has is used as given
    line = pipe.summary_line(st)
    assert line.startswith("1234.5 fps |")
    assert f"bad-2 {m['bad2_answered_mean']:.2f} % of answered, density {m['density_mean']:.1f} %" in line
    assert f"filled {m['bad2_filled_mean']:.2f} %" in line


def test_pipeline_bad_args():
    with pytest.raises(TypeError, match="process must be callable"):
        Pipeline(sim_source(1), "not callable")
    with pytest.raises(ValueError, match="max_frames must be >= 0"):
        Pipeline(sim_source(1), lambda f: f, max_frames=-1)
    with pytest.raises(TypeError, match="matcher must be a Matcher"):
        Fusion(object())


@pytest.mark.parametrize("values", ["too_far", "negative", "nan"])
def test_fusion_without_usable_points_is_no_depth(values):
    """A sparse map whose points are all unusable (d >= width, d < 0, NaN) counts as no depth.

    The matcher runs on the raw pair and no_depth is counted, like a frame without depth.
    """
    from vpp_service.matchers import build_matcher
    from vpp_service.vpp import VPPConfig

    src, got = sim_source(1, sensor="uniform"), []
    src.open()
    src.run(lambda f: got.append(f) or True, lambda r: None)
    frame = got[0]
    W = frame.shape[1]
    sparse = np.zeros(frame.shape, np.float32)
    sparse[::7, ::5] = {"too_far": W + 3.0, "negative": -2.0, "nan": np.nan}[values]
    matcher = build_matcher("sgbm", {"max_disparity": 32})
    fusion = Fusion(matcher, VPPConfig())
    res = fusion(frame.with_(sparse_disparity=sparse, sensor_depth=None))
    assert fusion.counters == {"vpp": 0, "no_depth": 1}
    assert res.left_vpp is None and res.right_vpp is None
    np.testing.assert_array_equal(res.disparity, np.asarray(matcher.compute(frame.left, frame.right)))


class PreparingProcess(SlowProcess):
    """Processing step with the optional ``prepare_next`` hook; the hook fails on odd frames."""

    def __init__(self, pipe_ref: list) -> None:
        super().__init__(pipe_ref, delay=0.0)
        self.prepared: list[int] = []

    def prepare_next(self, frame) -> None:
        self.prepared.append(frame.seq)
        if frame.seq % 2:
            raise RuntimeError("optional work failed")


def test_prepare_next_runs_after_each_result_and_cannot_break_the_service():
    ref: list = []
    proc = PreparingProcess(ref)
    sink = CollectSink()
    pipe = Pipeline(sim_source(6), proc, [sink], input_policy="block", output_policy="block")  # no race with the sinks
    ref.append(pipe)
    run(pipe)
    assert proc.prepared == [r.frame.seq for r in sink.results] == list(range(6))
    assert pipe.counters["processed"] == 6 and pipe.counters["errors"] == 0


@pytest.mark.parametrize(("pattern", "cached"), [("random", True), ("histogram", False)])
def test_fusion_prepare_next_caches_the_next_frames_pattern_table(pattern, cached):
    from vpp_service.matchers import build_matcher
    from vpp_service.vpp import VPPConfig
    from vpp_service.vpp.rng import _kernel_table

    src, got = sim_source(1, sensor="uniform"), []
    src.open()
    src.run(lambda f: got.append(f) or True, lambda r: None)
    frame = got[0].with_(seq=41)
    fusion = Fusion(build_matcher("sgbm", {"max_disparity": 32}), VPPConfig(pattern=pattern), seed=1000)
    _kernel_table.cache_clear()
    fusion.prepare_next(frame)
    assert _kernel_table.cache_info().currsize == int(cached)
    before = _kernel_table.cache_info()
    res = fusion(frame.with_(seq=42))  # seed 1042: the prepared table
    after = _kernel_table.cache_info()
    if cached:
        assert (after.hits - before.hits, after.misses - before.misses) == (1, 0)
    # preparing changes nothing in the output
    _kernel_table.cache_clear()
    again = fusion(frame.with_(seq=42))
    np.testing.assert_array_equal(res.left_vpp, again.left_vpp)
    np.testing.assert_array_equal(res.right_vpp, again.right_vpp)


def test_every_loss_is_in_one_dropped_count_with_its_cause():
    """Losses of the source (its own ``losses()``), the queues and the sinks all add up in ``counters["dropped"]``."""
    ref = []
    source = sim_source(30)
    source.losses = lambda: {"source_ring": 3, "sync": 2}  # a source reporting its own losses
    sink = CollectSink()
    sink.stats = lambda: {"written": 0, "dropped": 4, "errors": 0}
    pipe = Pipeline(source, SlowProcess(ref, delay=0.01), [sink], input_size=1, input_policy="latest")
    ref.append(pipe)
    run(pipe)
    st = pipe.status()
    d = st["dropped"]
    assert d["source_ring"] == 3 and d["sync"] == 2 and d["sink.CollectSink"] == 4 and d["input_queue"] > 0
    assert st["counters"]["dropped"] == sum(d.values()) == pipe.counters["dropped"]
    assert set(d) >= {"input_queue", "shutdown", "sink.CollectSink"}  # the output stage is gone: each sink its queue


class Unanswered:
    """A process step whose frames stay on a server that does not answer until ``release`` is set."""

    def __init__(self) -> None:
        self.release = threading.Event()
        self.started = 0
        self.lock = threading.Lock()

    def __call__(self, frame: StereoFrame) -> FusionResult:
        with self.lock:
            self.started += 1
        self.release.wait(30)
        return FusionResult(frame=frame, disparity=np.zeros(frame.shape, np.float32))


@pytest.mark.parametrize("in_flight", [1, 4])
def test_a_stop_that_times_out_counts_the_frames_still_being_matched(in_flight):
    """Every frame received is published or lost under ``shutdown``, also those a stop left on the server."""
    step, sink = Unanswered(), CollectSink()
    pipe = Pipeline(sim_source(30, rate_hz=100), step, [sink], input_size=2, input_policy="latest", in_flight=in_flight)
    pipe.start()
    assert pipe.source.finished.wait(20)  # every frame emitted: on the server, queued behind it or dropped
    deadline = time.monotonic() + 20
    while step.started < in_flight and time.monotonic() < deadline:
        time.sleep(0.01)
    queued = len(pipe.input)
    assert step.started == in_flight and queued >= 1
    t0 = time.monotonic()
    pipe.stop(0.5)
    assert time.monotonic() - t0 < 4.0  # the stop did not wait for the server
    st = pipe.status()
    c, d = st["counters"], st["dropped"]
    assert c["received"] == 30 and c["processed"] == c["published"] == 0 and sink.results == []
    assert d["shutdown"] >= in_flight + queued  # the frames on the server and those queued behind them
    assert d["shutdown"] + d["input_queue"] == c["received"]  # each frame counted once
    assert c["dropped"] == sum(d.values()) == c["received"]
    step.release.set()  # the server answers late: nothing is published or counted twice
    time.sleep(0.5)
    assert pipe.status()["counters"] == c and pipe.status()["dropped"] == d and sink.results == []


def test_block_end_to_end_through_zenoh_loses_nothing(zenoh_endpoint):
    """Policy block, a reliable BLOCK publisher at ~4x the processing rate: every frame is processed, 0 dropped."""
    n = 40
    with (
        zenoh.open(zenoh_test_config(listen=[zenoh_endpoint])) as svc,
        zenoh.open(zenoh_test_config(connect=[zenoh_endpoint])) as cam,
    ):
        source = build_source("zenoh", {"ring_size": 2}, SourceContext(rig="z", session=svc))
        ref = []
        sink = CollectSink()
        pipe = Pipeline(source, SlowProcess(ref, delay=0.02), [sink], input_size=2, input_policy="block", rig="z")
        ref.append(pipe)
        pipe.start()
        pub = cam.declare_publisher(
            "vpp/z/in/frame", congestion_control=zenoh.CongestionControl.BLOCK, reliability=zenoh.Reliability.RELIABLE
        )
        try:
            time.sleep(0.3)  # let the subscription propagate
            base = make_frame().with_(rig="z")  # the served rig (others are rejected)
            for seq in range(n):
                pub.put(wire.encode_frame(base.with_(seq=seq)))
                time.sleep(0.005)
            deadline = time.monotonic() + 10
            while len(sink.results) < n and time.monotonic() < deadline:
                time.sleep(0.02)
        finally:
            pub.undeclare()
            pipe.stop(2.0)
        assert [r.frame.seq for r in sink.results] == list(range(n))
        assert pipe.status()["counters"]["dropped"] == 0


def test_fps_is_measured_over_a_recent_window(monkeypatch):
    """Fps falls to 0 once frames stop coming (not processed / uptime, which only decays)."""
    from vpp_service.service import ledger as ledger_module

    monkeypatch.setattr(ledger_module, "FPS_WINDOW_S", 0.5)
    sink = CollectSink()
    pipe = Pipeline(sim_source(10), lambda f: FusionResult(f, np.zeros(f.shape, np.float32)), [sink])
    pipe.start()
    assert pipe.wait(20)
    assert pipe.status()["fps"] > 0
    time.sleep(0.6)
    st = pipe.status()
    assert st["counters"]["processed"] > 0 and st["uptime_s"] > 0
    assert st["fps"] == 0.0
    pipe.stop(2.0)


class ForgedRigSource(Source):
    """Emits frames of the served rig interleaved with frames whose rig a message could have forged."""

    Options = None
    RIGS = ("rig0", "../../x/relative", "rig0", "/abs/path", "rig1", ".hidden", "a\x00b", "rig0")

    def run(self, emit, reject):
        for seq, rig in enumerate(self.RIGS):
            emit(FRAME.with_(rig=rig, seq=seq))


FRAME = StereoFrame(np.zeros((4, 6, 3), np.uint8), np.zeros((4, 6, 3), np.uint8), rig="rig0")


def test_frames_of_another_rig_are_rejected_before_any_sink():
    sink = CollectSink()
    pipe = Pipeline(
        ForgedRigSource(None, SourceContext(rig="rig0")),
        lambda f: FusionResult(f, np.zeros(f.shape, np.float32)),
        [sink],
        input_policy="block",
    )
    run(pipe)
    c = pipe.counters
    assert c["received"] == 8 and c["rejected"] == 5 and c["processed"] == 3
    assert [r.frame.seq for r in sink.results] == [0, 2, 7]
    assert {r.frame.rig for r in sink.results} == {"rig0"}


class StampSource(Source):
    """Emits served-rig frames whose sender stamps are hostile (far past, zero, far future)."""

    Options = None

    def run(self, emit, reject):
        for seq, stamp in enumerate((1, 0, (1 << 63) - 1, 5)):
            emit(FRAME.with_(seq=seq, stamp_ns=stamp))


def test_latency_is_measured_from_receive_time_not_the_senders_stamp():
    pipe = Pipeline(
        StampSource(None, SourceContext(rig="rig0")),
        lambda f: FusionResult(f, np.zeros(f.shape, np.float32)),
        [CollectSink()],
        input_policy="block",
    )
    run(pipe)
    lat = pipe.status()["timing_ms"]["latency"]
    assert lat["n"] == 4
    assert 0 <= lat["p99"] < 60_000  # the stamps would say 56 years, 0 or minus 236 years


def test_summary_line_says_what_it_waits_on_before_the_first_frame(sessions):
    from vpp_service.sources.base import SourceContext, build_source

    listener, _ = sessions
    src = build_source("zenoh", {}, SourceContext(rig="r1", prefix="vpp", session=listener))
    pipe = Pipeline(src, lambda f: None, [], rig="r1")  # type: ignore[arg-type, return-value]
    src.open()
    try:
        line = pipe.summary_line()
    finally:
        src.stop(1.0)
    assert line == "waiting for frames on vpp/r1/in/frame: nothing has arrived yet"


def test_a_status_query_flood_is_served_from_one_snapshot_per_period(sessions):
    """300 @status queries as fast as a peer sends them: at most one status build per 100 ms, the rest counted."""
    from vpp_service.service.ledger import STATUS_SNAPSHOT_S

    listener, peer = sessions
    process = lambda f: FusionResult(frame=f, disparity=np.zeros(f.shape, np.float32))  # noqa: E731
    pipe = Pipeline(sim_source(0, rate_hz=50.0), process, [], session=listener, rig="rig0")
    pipe.start()
    try:
        assert wait_until(lambda: any(r.ok for r in peer.get("vpp/rig0/@status", timeout=1.0)))  # routes are up
        before = pipe.status()["status_queries"]
        t0 = time.monotonic()
        replies = []
        for _ in range(300):
            replies += [r.ok.payload.to_string() for r in peer.get("vpp/rig0/@status", timeout=5.0) if r.ok]
        elapsed = time.monotonic() - t0
        after = pipe.status()["status_queries"]
    finally:
        pipe.stop(2.0)
    q = {k: after[k] - before[k] for k in after}
    assert len(replies) == 300 and all(json.loads(r)["rig"] == "rig0" for r in replies)
    assert q["queries"] == 300 and q["snapshots"] + q["cached"] == 300
    assert q["snapshots"] <= elapsed / STATUS_SNAPSHOT_S + 2 and q["cached"] > 0, (q, elapsed)


class HangingSink(CollectSink):
    """A sink whose library hangs in close (a Rerun stream stuck disconnecting from a full disk)."""

    def close(self, timeout: float = 5.0) -> None:
        time.sleep(30)


def test_shutdown_is_bounded_whatever_a_sink_does_and_names_it():
    pipe = Pipeline(
        sim_source(2),
        lambda f: FusionResult(frame=f, disparity=np.zeros(f.shape, np.float32)),
        [HangingSink(), CollectSink()],
        input_policy="block",
    )
    pipe.start()
    assert pipe.wait(20)
    t0 = time.monotonic()
    pipe.stop(1.0)
    assert time.monotonic() - t0 < 4.0
    assert pipe.unfinished_sinks == ["HangingSink"]


def test_closing_line_never_claims_a_file_it_did_not_write(tmp_path):
    from vpp_service.cli.run import closing_line
    from vpp_service.service.config import DEFAULT_CONFIG, validate_config

    cfg = validate_config({**DEFAULT_CONFIG, "service": {"out": str(tmp_path)}})
    line = closing_line(cfg, {"processed": 2})
    assert "wrote" not in line and f"NOT written: {tmp_path / 'summary.json'}, {tmp_path / 'vpp.rrd'}" in line
    (tmp_path / "summary.json").write_text("{}")
    line = closing_line(cfg, {"processed": 2})
    assert f"wrote {tmp_path / 'summary.json'}; NOT written: {tmp_path / 'vpp.rrd'}" in line


class StalledSink(CollectSink):
    """A sink whose consumer stalls (a viewer, the network): its writes wait on ``release``."""

    def __init__(self, size: int) -> None:
        super().__init__()
        self.size, self.release = size, threading.Event()

    def queue_spec(self) -> QueueSpec:
        return QueueSpec(size=self.size)

    def write(self, result: FusionResult) -> None:
        self.release.wait(10)
        super().write(result)


def test_each_sink_has_its_own_queue_a_stalled_one_drops_only_its_own():
    """The pipeline owns the buffers: a stalled sink's full queue drops (counted as its loss); the others get all."""
    stalled, fine = StalledSink(size=2), CollectSink()
    pipe = Pipeline(
        sim_source(10),
        lambda f: FusionResult(frame=f, disparity=np.zeros(f.shape, np.float32)),
        [stalled, fine],
        input_policy="block",
        output_size=16,  # the fine sink's queue holds every result (the stalled one has its own size 2)
    )
    pipe.start()
    assert wait_until(lambda: pipe.status()["counters"]["processed"] == 10)
    stalled.release.set()
    assert pipe.wait(20)
    st = pipe.status()
    pipe.stop(2.0)
    assert len(fine.results) == 10 and st["queues"]["sink.StalledSink"]["size"] == 2
    lost = st["dropped"]["sink.StalledSink"]
    assert lost > 0 and len(stalled.results) + lost == 10 and st["dropped"].get("sink.CollectSink") == 0
    assert st["counters"]["published"] == 10 - lost  # a result one sink dropped is not published
    assert [r.frame.seq for r in stalled.results] == sorted(r.frame.seq for r in stalled.results)


def test_a_sink_that_must_not_drop_holds_the_pipeline_back():
    stalled = StalledSink(size=1)
    stalled.queue_spec = lambda: QueueSpec(size=1, policy="block")  # a recording: never drops
    pipe = Pipeline(
        sim_source(6),
        lambda f: FusionResult(frame=f, disparity=np.zeros(f.shape, np.float32)),
        [stalled],
        input_policy="block",
    )
    pipe.start()
    time.sleep(0.5)
    assert pipe.status()["counters"]["processed"] <= 3  # waiting for the sink, not dropping
    stalled.release.set()
    assert pipe.wait(20)
    pipe.stop(2.0)
    assert len(stalled.results) == 6 and pipe.status()["counters"]["dropped"] == 0


def test_start_and_finish_run_on_the_sinks_own_thread():
    class Hooked(CollectSink):
        def start(self) -> None:
            self.started_on = threading.current_thread().name

        def write(self, result: FusionResult) -> None:
            self.wrote_on = threading.current_thread().name
            super().write(result)

        def finish(self) -> None:
            self.finished_on = threading.current_thread().name

    sink = Hooked()
    run(Pipeline(sim_source(2), lambda f: FusionResult(frame=f, disparity=np.zeros(f.shape, np.float32)), [sink]))
    assert sink.started_on == sink.wrote_on == sink.finished_on == "sink-Hooked"


def wait_until(cond, timeout: float = 10.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and not cond():
        time.sleep(0.01)
    return cond()
