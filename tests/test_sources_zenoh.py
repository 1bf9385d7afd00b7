"""zenoh source over real sessions on 127.0.0.1: decode, reject malformed, separate-topics sync."""

from __future__ import annotations

import math
import threading
import time

import msgpack
import numpy as np
import pytest
import zenoh

from helpers.frames import make_frame
from vpp_service.sources.base import SourceContext, build_source
from vpp_service.transport import wire


def started(session, **opts):
    src = build_source("zenoh", opts, SourceContext(rig="z", session=session))
    frames, rejects = [], []
    src.open()
    src.start(lambda f: frames.append(f) or True, rejects.append)
    time.sleep(0.3)  # let the subscription propagate
    return src, frames, rejects


def wait_for(cond, timeout=5.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and not cond():
        time.sleep(0.01)
    return cond()


def bad_payloads():
    good = msgpack.unpackb(wire.encode_frame(make_frame()), raw=False)
    nan_calib = {**good, "calib": {"f": math.nan, "baseline": 0.1}}
    huge = {**good, "left": {**good["left"], "h": 1 << 40, "w": 1 << 40}}
    short = {**good, "right": {**good["right"], "data": b"\0" * 5}}
    wrong_type = {**good, "seq": "seven"}
    return [
        wire.encode_frame(make_frame())[:-7],
        msgpack.packb(nan_calib),
        msgpack.packb(huge),
        msgpack.packb(short),
        msgpack.packb(wrong_type),
    ]


def test_frames_decoded_and_malformed_rejected(sessions):
    svc, cam = sessions
    src, frames, rejects = started(svc, ring_size=16)
    try:
        key = "vpp/z/in/frame"
        cam.put(key, wire.encode_frame(make_frame(seed=1)), congestion_control=zenoh.CongestionControl.BLOCK)
        for p in bad_payloads():
            cam.put(key, p, congestion_control=zenoh.CongestionControl.BLOCK)
        cam.put(
            key, wire.encode_frame(make_frame(seed=2).with_(seq=8)), congestion_control=zenoh.CongestionControl.BLOCK
        )
        assert wait_for(lambda: len(frames) + len(rejects) == 7)
        assert [f.seq for f in frames] == [7, 8]
        np.testing.assert_array_equal(frames[0].left, make_frame(seed=1).left)
        assert "decode" in frames[0].meta["timing_ms"]
        # metric points arrive as their disparity alone (decoded as decode_frame(metric_map=False) does)
        sent = wire.decode_frame(wire.encode_frame(make_frame(seed=1)))
        assert frames[0].sensor_depth is None and sent.sensor_depth is not None
        np.testing.assert_array_equal(frames[0].sparse_disparity, sent.sparse_disparity)
        st = src.stats()
        assert st["rejected"] == 5 and st["emitted"] == 2 and st["received"] == 7
        assert any("calib.f" in r for r in rejects) and any("left.h" in r for r in rejects)
    finally:
        src.stop(2.0)


@pytest.mark.parametrize("sync", ["exact", "approximate"])
def test_separate_topics_sync_and_drops(sessions, sync):
    svc, cam = sessions
    src, frames, rejects = started(svc, topics="separate", sync=sync, sync_threshold_ms=1.0, ring_size=16)
    try:
        base = make_frame()
        for seq in range(3):
            fr = base.with_(seq=seq, stamp_ns=1_000_000_000 + seq * 100_000_000)
            for part in ("left", "right") if seq != 1 else ("left", "right", "depth"):
                cam.put(
                    f"vpp/z/in/{part}", wire.encode_part(fr, part), congestion_control=zenoh.CongestionControl.BLOCK
                )
                time.sleep(0.02)  # keep arrival order across topics
        assert wait_for(lambda: len(frames) == 1)
        time.sleep(0.2)
        assert len(frames) == 1 and frames[0].seq == 1 and frames[0].sensor_depth is not None
        np.testing.assert_array_equal(frames[0].right, base.right)
        st = src.stats()["sync"]
        assert st["matched"] == 1 and st["dropped"] == 2  # left/right of seq 0
        assert st["pending"] == {"left": 1, "right": 1, "depth": 0}
        assert not rejects
    finally:
        src.stop(2.0)


def test_needs_session():
    src = build_source("zenoh", {}, SourceContext())
    with pytest.raises(ValueError, match="session"):
        src.open()


@pytest.mark.parametrize(
    "opts",
    [
        {"ring_size": 0},
        {"topics": "both"},
        {"sync_threshold_ms": -1.0},
        {"topics": "separate", "ring_sizes": {"center": 2}},
        {"topics": "separate", "ring_sizes": {"left": 0}},
        {"topics": "separate", "ring_sizes": {"depth": True}},
        {"ring_sizes": {"depth": 8}},
    ],
)
def test_bad_options(opts):
    with pytest.raises(ValueError, match=r"source\.zenoh"):
        build_source("zenoh", opts)


def test_ring_keeps_newest_and_counts_drops(sessions):
    """A burst while the receive thread is not draining keeps the newest ring_size frames.

    The rest are counted as ring_dropped (no silent loss).
    """
    svc, cam = sessions
    src = build_source("zenoh", {"ring_size": 3}, SourceContext(rig="z", session=svc))
    src.open()
    try:
        time.sleep(0.3)  # let the subscription propagate
        base = make_frame()
        for seq in range(10):
            cam.put(
                "vpp/z/in/frame",
                wire.encode_frame(base.with_(seq=seq)),
                congestion_control=zenoh.CongestionControl.BLOCK,
            )
        assert wait_for(lambda: src.stats()["ring_dropped"] == 7)
        frames = []
        src.start(lambda f: frames.append(f) or True, lambda r: None)
        assert wait_for(lambda: len(frames) == 3)
        assert [f.seq for f in frames] == [7, 8, 9]
        st = src.stats()
        assert st["received"] == 3 and st["ring_dropped"] == 7
    finally:
        src.stop(2.0)


@pytest.mark.parametrize("policy", ["latest", "block"])
def test_messages_are_checked_on_zenohs_receive_thread(sessions, policy):
    """Under both policies the callback runs on Zenoh's own receive thread, not a Python thread fed by a channel.

    A channel would queue a junk flood ahead of valid frames (and its busy Python thread would starve the
    processing thread); on the receive thread a flood faster than the checks is held back on its own link.
    """
    svc, cam = sessions
    src = build_source("zenoh", {}, SourceContext(rig="z", session=svc))
    src.input_policy = policy
    threads: list[threading.Thread] = []
    src.open()
    src.start(lambda f: True, lambda r: threads.append(threading.current_thread()))
    try:
        time.sleep(0.3)  # let the subscription propagate
        cam.put("vpp/z/in/frame", b"\xc1", congestion_control=zenoh.CongestionControl.BLOCK)
        assert wait_for(lambda: len(threads) == 1)
        # a thread Python did not start: Zenoh's receive thread calling in (an indirect callback's is a Thread)
        assert isinstance(threads[0], threading._DummyThread), threads[0]
        assert src.stats()["rejected"] == 1
    finally:
        src.stop(2.0)


def test_stop_is_prompt_when_idle(sessions):
    """The idle receive thread sleeps on an event: stop() wakes it at once."""
    svc, _ = sessions
    src, _, _ = started(svc, poll_s=1.0)
    t0 = time.monotonic()
    src.stop(2.0)
    assert time.monotonic() - t0 < 0.5
    assert src.finished.wait(1.0)


def test_per_topic_ring_sizes(sessions):
    """Separate topics with a deeper depth ring: each topic keeps and drops on its own.

    Each topic keeps its own newest samples and counts its own drops; exact sync
    then joins the seqs all kept.
    """
    svc, cam = sessions
    src = build_source(
        "zenoh",
        {"topics": "separate", "ring_size": 2, "ring_sizes": {"depth": 5}, "sync_queue_size": 8},
        SourceContext(rig="z", session=svc),
    )
    src.open()
    try:
        time.sleep(0.3)  # let the subscriptions propagate
        base = make_frame()
        for seq in range(6):
            fr = base.with_(seq=seq, stamp_ns=1_000_000_000 + seq * 100_000_000)
            for part in ("depth", "left", "right"):
                cam.put(
                    f"vpp/z/in/{part}", wire.encode_part(fr, part), congestion_control=zenoh.CongestionControl.BLOCK
                )
        assert wait_for(lambda: src.stats()["ring_dropped"] == 4 + 4 + 1)
        frames = []
        src.start(lambda f: frames.append(f) or True, lambda r: None)
        assert wait_for(lambda: len(frames) == 2)
        time.sleep(0.2)
        assert [f.seq for f in frames] == [4, 5]
    finally:
        src.stop(2.0)


def put_block(cam, key, payload):
    cam.put(key, payload, congestion_control=zenoh.CongestionControl.BLOCK)


def test_junk_never_displaces_valid_frames(sessions):
    """A flood of rejected messages on a full ring leaves the valid frames queued (the old ring evicted them)."""
    svc, cam = sessions
    src = build_source("zenoh", {"ring_size": 2}, SourceContext(rig="z", session=svc))
    src.open()
    try:
        time.sleep(0.3)  # let the subscription propagate
        base = make_frame()
        for seq in (1, 2):
            put_block(cam, "vpp/z/in/frame", wire.encode_frame(base.with_(seq=seq)))
        for p in bad_payloads() * 10:
            put_block(cam, "vpp/z/in/frame", p)
        assert wait_for(lambda: src.stats()["rejected"] == 50)
        frames = []
        src.start(lambda f: frames.append(f) or True, lambda r: None)
        assert wait_for(lambda: len(frames) == 2)
        assert [f.seq for f in frames] == [1, 2]
        assert src.stats()["ring_dropped"] == 0 and src.losses()["source_ring"] == 0
    finally:
        src.stop(2.0)


def test_forged_depth_part_cannot_destroy_the_victims_frame(sessions):
    """Separate topics: a 4x6 depth part (images 6x8) with seq 5 arrives first; frame 5 still goes through."""
    svc, cam = sessions
    src, frames, rejects = started(svc, topics="separate", ring_size=16)
    try:
        victim = make_frame().with_(seq=5, stamp_ns=1_000_000_000)
        forged = make_frame(h=4, w=6).with_(seq=5, stamp_ns=1_000_000_000)
        put_block(cam, "vpp/z/in/depth", wire.encode_part(forged, "depth"))
        time.sleep(0.05)
        for part in ("left", "right", "depth"):
            put_block(cam, f"vpp/z/in/{part}", wire.encode_part(victim, part))
            time.sleep(0.02)
        assert wait_for(lambda: len(frames) == 1)
        assert frames[0].seq == 5 and frames[0].sensor_depth.shape == victim.left.shape[:2]
        st = src.stats()
        assert st["sync_inconsistent"] == 1 and src.losses()["sync_inconsistent"] == 1 and not rejects
    finally:
        src.stop(2.0)


def test_block_policy_backpressures_instead_of_dropping(sessions):
    """Under the block input policy a full ring holds Zenoh back: every frame of a burst arrives, in order."""
    svc, cam = sessions
    src = build_source("zenoh", {"ring_size": 2}, SourceContext(rig="z", session=svc))
    src.input_policy = "block"
    src.open()
    pub = cam.declare_publisher(
        "vpp/z/in/frame", congestion_control=zenoh.CongestionControl.BLOCK, reliability=zenoh.Reliability.RELIABLE
    )
    frames = []
    try:
        time.sleep(0.3)  # let the subscription propagate
        base = make_frame()
        for seq in range(12):  # the ring holds 2: the rest wait in Zenoh (the publisher's puts are not lost)
            pub.put(wire.encode_frame(base.with_(seq=seq)))
        time.sleep(0.3)
        assert src.stats()["ring_dropped"] == 0
        src.start(lambda f: frames.append(f) or True, lambda r: None)
        assert wait_for(lambda: len(frames) == 12)
        assert [f.seq for f in frames] == list(range(12))
        assert src.losses() == {"source_ring": 0, "sync": 0, "sync_inconsistent": 0}
    finally:
        pub.undeclare()
        src.stop(2.0)


def test_block_policy_stop_releases_a_waiting_callback(sessions):
    """A callback waiting for room gives up when the source stops (the stop stays bounded)."""
    svc, cam = sessions
    src = build_source("zenoh", {"ring_size": 1}, SourceContext(rig="z", session=svc))
    src.input_policy = "block"
    src.open()
    time.sleep(0.3)
    for seq in range(3):
        put_block(cam, "vpp/z/in/frame", wire.encode_frame(make_frame().with_(seq=seq)))
    time.sleep(0.3)
    t0 = time.monotonic()
    src.stop(2.0)
    assert time.monotonic() - t0 < 1.5


def test_oversized_message_is_rejected_in_the_callback_before_buffering(sessions):
    svc, cam = sessions
    # opened, not started: nothing drains the ring, so only the callback can reject and count
    src = build_source("zenoh", {"max_message_mb": 0.5}, SourceContext(rig="z", session=svc))
    src.open()
    try:
        time.sleep(0.3)
        cam.put("vpp/z/in/frame", bytes(600 * 1024))
        cam.put("vpp/z/in/frame", wire.encode_frame(make_frame()))
        assert wait_for(lambda: src.stats()["received"] == 1)
        st = src.stats()
        assert st["rejected"] == 1 and st["ring_dropped"] == 0
    finally:
        src.close()


@pytest.mark.parametrize("opts", [{"max_pixels": 0}, {"max_pixels": True}, {"max_pixels": 1 << 29}])
def test_bad_max_pixels(opts):
    with pytest.raises(ValueError, match="max_pixels"):
        build_source("zenoh", opts, SourceContext(rig="z"))


def test_max_pixels_option_is_applied(sessions):
    svc, cam = sessions
    src, frames, rejects = started(svc, max_pixels=6 * 8 - 1)
    try:
        cam.put("vpp/z/in/frame", wire.encode_frame(make_frame(h=6, w=8)))
        assert wait_for(lambda: len(rejects) == 1)
        assert "exceeds the limit of 47" in rejects[0] and frames == []
    finally:
        src.stop(2.0)
