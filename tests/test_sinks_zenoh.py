"""zenoh sink over real sessions: lazy outputs, wire decoding by a subscriber, bounded close."""

from __future__ import annotations

import time

import numpy as np
import pytest
import zenoh

from helpers.frames import make_frame
from helpers.zenoh_loopback import collect
from vpp_service.frame import FusionResult
from vpp_service.sinks.base import SinkContext, build_sink
from vpp_service.transport import wire


def result(seq):
    fr = make_frame().with_(seq=seq)
    disp = np.full(fr.shape, 2.0 + seq, np.float32)
    return FusionResult(
        frame=fr, disparity=disp, depth=disp + 1, left_vpp=fr.left, right_vpp=fr.right, timing_ms={"match": 1.0}
    )


@pytest.mark.parametrize("outputs", [["disparity"], ["disparity", "depth", "left_vpp", "right_vpp"]])
def test_publishes_selected_outputs(sessions, outputs):
    svc, client = sessions
    sub = client.declare_subscriber("vpp/s/out/**", zenoh.handlers.FifoChannel(64))
    sink = build_sink(
        "zenoh", {"outputs": outputs, "on_request": [], "queue_size": 8}, SinkContext(rig="s", session=svc)
    )
    sink.open()
    time.sleep(0.3)
    for seq in range(3):
        sink.write(result(seq))
    sink.close(3.0)
    got = collect(sub, 3 * len(outputs))
    assert sorted({str(s.key_expr).rsplit("/", 1)[1] for s in got}) == sorted(outputs)
    disp = [wire.decode_output(s.payload.to_bytes()) for s in got if str(s.key_expr).endswith("disparity")]
    assert [d.seq for d in disp] == [0, 1, 2]
    for d in disp:
        np.testing.assert_array_equal(d.data, np.full((6, 8), 2.0 + d.seq, np.float32))
    if "left_vpp" in outputs:
        img = next(s for s in got if str(s.key_expr).endswith("left_vpp"))
        np.testing.assert_array_equal(wire.decode_output_image(img.payload.to_bytes())[1], make_frame().left)
    assert sink.stats()["written"] == 3


@pytest.mark.parametrize("pool_mb", [0, 16])
def test_large_outputs_identical_with_and_without_shared_memory(sessions, pool_mb):
    """A 3 MB disparity map comes through the same whether it left from the pool or not."""
    svc, client = sessions
    sub = client.declare_subscriber("vpp/m/out/disparity", zenoh.handlers.FifoChannel(8))
    # lossless here: under DROP a busy machine may drop a 3 MB put, and this test is about the bytes
    opts = {"outputs": ["disparity"], "shm_pool_mb": pool_mb, "congestion_control": "block"}
    sink = build_sink("zenoh", opts, SinkContext(rig="m", session=svc))
    sink.open()
    time.sleep(0.3)
    fr = make_frame().with_(seq=7)
    disp = np.random.default_rng(3).random((750, 1000), dtype=np.float32)
    big = fr.with_(left=np.zeros((750, 1000, 3), np.uint8), right=np.zeros((750, 1000, 3), np.uint8))
    sink.write(FusionResult(frame=big, disparity=disp, depth=None, left_vpp=None, right_vpp=None, timing_ms={}))
    sink.close(3.0)
    got = collect(sub, 1)
    assert len(got) == 1
    np.testing.assert_array_equal(wire.decode_output(got[0].payload.to_bytes()).data, disp)
    shm = sink.stats()["shm"]
    assert shm["shm_puts"] + shm["plain_puts"] == 1 and shm["fallbacks"] == 0
    if pool_mb == 0:
        assert shm["plain_puts"] == 1


def test_on_request_outputs_only_while_subscribed(sessions):
    svc, client = sessions
    disp_sub = client.declare_subscriber("vpp/s/out/disparity", zenoh.handlers.FifoChannel(64))
    sink = build_sink("zenoh", {"outputs": ["disparity"], "queue_size": 8}, SinkContext(rig="s", session=svc))
    sink.open()
    time.sleep(0.3)
    for seq in range(3):
        sink.write(result(seq))
    time.sleep(0.5)
    assert sink.stats()["unrequested"] == 9  # left_vpp, right_vpp, sparse: nobody asked, never serialized
    sub = client.declare_subscriber("vpp/s/out/sparse", zenoh.handlers.FifoChannel(64))
    time.sleep(0.5)
    res = result(3)
    sparse = np.full(res.frame.shape, np.nan, np.float32)
    sparse[3, 5], sparse[0, 1] = 7.5, 2.0
    res.frame = res.frame.with_(sparse_disparity=sparse)
    sink.write(res)
    got = collect(sub, 1)
    sink.close(3.0)
    assert len(collect(disp_sub, 4)) == 4 and sink.stats()["unrequested"] == 11  # the pair still unrequested
    pts = wire.decode_output_points(got[0].payload.to_bytes())
    assert (pts.seq, pts.h, pts.w) == (3, *res.frame.shape)
    assert pts.points.tolist() == [[1.0, 0.0, 2.0], [5.0, 3.0, 7.5]]  # (x, y, disparity), raster order


@pytest.mark.parametrize(("policy", "product"), [(None, "DROP"), ("drop", "DROP"), ("block", "BLOCK")])
def test_congestion_settings(sessions, policy, product):
    # DROP by default: a consumer that stops reading must not slow the others down to its pace
    svc, _ = sessions
    opts: dict[str, object] = {"outputs": ["disparity", "left_vpp"]}
    if policy is not None:
        opts["congestion_control"] = policy
    sink = build_sink("zenoh", opts, SinkContext(session=svc))
    sink.open()
    try:
        assert sink._pubs["disparity"].congestion_control == getattr(zenoh.CongestionControl, product)
        assert sink._pubs["disparity"].priority == zenoh.Priority.DATA
        assert sink._pubs["left_vpp"].congestion_control == zenoh.CongestionControl.DROP
        assert sink._pubs["left_vpp"].priority == zenoh.Priority.DATA_LOW
    finally:
        sink.close(1.0)


def test_write_before_open_is_an_error(sessions):
    svc, _ = sessions
    sink = build_sink("zenoh", {"queue_size": 1}, SinkContext(session=svc))
    with pytest.raises(RuntimeError, match="not open"):
        sink.write(result(0))
    assert sink.queue_spec().size == 1  # the pipeline queues queue_size results for it


def test_close_is_bounded_without_peers(sessions):
    svc, _ = sessions
    sink = build_sink("zenoh", {}, SinkContext(session=svc))
    sink.open()
    sink.write(result(0))
    t0 = time.monotonic()
    sink.close(2.0)
    assert time.monotonic() - t0 < 3.0


@pytest.mark.parametrize(
    "opts",
    [
        {"outputs": []},
        {"outputs": ["normals"]},
        {"outputs": ["depth", "depth"]},
        {"queue_size": 0},
        {"image_enc": "gif"},
        {"shm_pool_mb": -1},
        {"shm_pool_mb": 5000},
        {"shm_pool_mb": "64"},
        {"points_stride": 0},
        {"points_stride": "4"},
    ],
)
def test_bad_options(opts):
    with pytest.raises(ValueError, match=r"sinks\.zenoh"):
        build_sink("zenoh", opts)


def test_needs_session():
    with pytest.raises(ValueError, match="session"):
        build_sink("zenoh", {}).open()


def test_points_output_over_zenoh(sessions):
    """``out/points`` from a depth-clipped fused result: a subscriber decodes the depth map's cloud."""
    from helpers.points import assert_cloud_is_depth, clipped_result

    svc, client = sessions
    sub = client.declare_subscriber("vpp/r1/out/points", zenoh.handlers.FifoChannel(8))
    opts = {"outputs": ["points"], "on_request": [], "points_stride": 2, "congestion_control": "block"}
    sink = build_sink("zenoh", opts, SinkContext(rig="r1", session=svc))
    assert type(sink).needs_depth(sink.options)
    sink.open()
    time.sleep(0.3)
    results = [clipped_result(seq) for seq in (1, 2)]
    for res in results:
        sink.write(res)
    sink.close(3.0)
    got = collect(sub, 2)
    assert len(got) == 2
    for sample, res in zip(got, results, strict=True):
        cloud = wire.decode_output_cloud(sample.payload.to_bytes())
        assert cloud.seq == res.frame.seq and cloud.stride == 2
        assert_cloud_is_depth(cloud.xyz, cloud.rgb, res, 2)


def test_publishes_confidence(sessions):
    """``confidence``: the float32 map as an OutputMap on out/confidence; needs_confidence asks the service for it."""
    from vpp_service.sinks.zenoh import ZenohSink

    svc, client = sessions
    sub = client.declare_subscriber("vpp/s/out/confidence", zenoh.handlers.FifoChannel(8))
    opts = {"outputs": ["disparity", "confidence"], "on_request": [], "congestion_control": "block"}
    sink = build_sink("zenoh", opts, SinkContext(rig="s", session=svc))
    assert ZenohSink.needs_confidence(sink.options)
    assert not ZenohSink.needs_confidence(build_sink("zenoh", {}, SinkContext(rig="s", session=svc)).options)
    sink.open()
    time.sleep(0.3)
    res = result(4)
    res.confidence = np.linspace(0, 1, 48, dtype=np.float32).reshape(6, 8)
    sink.write(res)
    sink.write(result(5))  # no confidence in this result: nothing published for it
    sink.close(3.0)
    got = collect(sub, 2, timeout=1.0)
    assert len(got) == 1
    out = wire.decode_output(got[0].payload.to_bytes())
    assert out.seq == 4
    np.testing.assert_array_equal(out.data, res.confidence)
