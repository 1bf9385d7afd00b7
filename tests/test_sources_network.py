"""The network sources' shared part over real Zenoh sessions on 127.0.0.1: bound, refuse, ring, drain, stop."""

from __future__ import annotations

import functools
import time

import pytest
import zenoh

from helpers.frames import make_frame
from vpp_service.frame import StereoFrame
from vpp_service.sources.base import Reject, SourceContext
from vpp_service.sources.network import NetworkSource, Refused

TOPICS = ("a", "b")


class Echo(NetworkSource[int]):
    """A network source with the least of its own: ``vpp/t/in/<topic>`` carries a decimal seq, ``junk`` is refused.

    A message taken from a ring becomes a frame of that seq; ``expire`` frames queued by the test are
    released by :meth:`_expire`.
    """

    def __init__(self, context: SourceContext, *, max_message_bytes: int = 64, poll_s: float = 0.05) -> None:
        super().__init__(None, context, max_message_bytes=max_message_bytes, poll_s=poll_s)
        self.ring_size = 2
        self.expire: list[StereoFrame] = []
        self._subs: list[zenoh.Subscriber[None]] = []

    def open(self) -> None:
        session = self.session("echo")
        self.open_rings(dict.fromkeys(TOPICS, self.ring_size))
        for topic in TOPICS:
            handler = zenoh.handlers.Callback(functools.partial(self._on_sample, topic), indirect=False)
            self._subs.append(session.declare_subscriber(f"vpp/t/in/{topic}", handler))

    def _topic_name(self, topic: str, sample: zenoh.Sample) -> str:
        return f"echo/{topic}"

    def _admit(self, topic: str, sample: zenoh.Sample, recv_ns: int) -> int:
        text = sample.payload.to_bytes()
        if text == b"junk":
            raise Refused("junk", "junk: not a number")
        return int(text)

    def _handle(self, topic: str, item: int, reject: Reject) -> list[StereoFrame]:
        return [make_frame(h=4, w=6).with_(seq=item)]

    def _expire(self) -> list[StereoFrame]:
        out, self.expire = self.expire, []
        return out

    def close(self) -> None:
        for sub in self._subs:
            sub.undeclare()
        self._subs.clear()


class EchoAtDrain(Echo):
    received_at = "drain"


def wait_for(cond, timeout=5.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and not cond():
        time.sleep(0.01)
    return cond()


def put(session: zenoh.Session, topic: str, payload: bytes) -> None:
    session.put(f"vpp/t/in/{topic}", payload, congestion_control=zenoh.CongestionControl.BLOCK)


@pytest.fixture
def opened(sessions):
    """An Echo source opened (not started: nothing drains its rings) on the service session, and the camera's."""
    svc, cam = sessions
    src = Echo(SourceContext(rig="t", session=svc), max_message_bytes=8)
    src.open()
    time.sleep(0.3)  # let the subscriptions propagate
    yield src, cam
    src.stop(2.0)


def test_without_a_session_the_error_names_the_section():
    with pytest.raises(ValueError, match=r"source\.echo: needs an open zenoh session"):
        Echo(SourceContext(rig="t")).open()


def test_an_oversized_message_is_refused_by_its_length_before_a_ring_slot(opened):
    src, cam = opened
    put(cam, "a", b"1")
    for _ in range(5):  # more than the ring holds: had they taken slots, the valid message would be gone
        put(cam, "a", b"9" * 9)
    assert wait_for(lambda: src.stats()["received"] == 6)
    st = src.stats()
    assert st["rejected"] == 5 and src.refused_by() == {"too_large": 5}
    assert st["ring_dropped"] == 0 and src.losses() == {"source_ring": 0}
    assert not any(k.startswith("rejected.") for k in st), st  # by cause only through refused_by()
    assert src._rings is not None and src._rings.take("a") == 1 and src._rings.take("a") is None


def test_the_subclass_refusal_is_counted_by_its_cause_and_reported(sessions):
    svc, cam = sessions
    src = Echo(SourceContext(rig="t", session=svc))
    frames: list[StereoFrame] = []
    rejects: list[str] = []
    src.open()
    src.start(lambda f: frames.append(f) or True, rejects.append)
    try:
        time.sleep(0.3)
        put(cam, "b", b"junk")
        put(cam, "b", b"x" * 65)
        put(cam, "b", b"7")
        assert wait_for(lambda: len(frames) == 1 and len(rejects) == 2)
    finally:
        src.stop(2.0)
    assert rejects == ["echo/b: junk: not a number", "echo/b: too_large: 65 bytes > max 64"]
    assert src.refused_by() == {"junk": 1, "too_large": 1} and frames[0].seq == 7
    st = src.stats()
    assert (st["received"], st["rejected"], st["emitted"], st["ring_dropped"]) == (3, 2, 1, 0)


@pytest.mark.parametrize(("cls", "received"), [(Echo, 5), (EchoAtDrain, 0)])
def test_a_full_ring_drops_its_oldest_under_latest_and_received_follows_the_subclass(sessions, cls, received):
    """``arrival`` counts what the callback got, a ring's drops included; ``drain`` only what was taken."""
    svc, cam = sessions
    src = cls(SourceContext(rig="t", session=svc))
    src.open()
    try:
        time.sleep(0.3)
        for seq in range(5):
            put(cam, "a", str(seq).encode())
        assert wait_for(lambda: src.stats()["ring_dropped"] == 3)
        assert src.stats()["received"] == received and src.losses() == {"source_ring": 3}
        assert src._rings is not None and [src._rings.take("a"), src._rings.take("a")] == [3, 4]
    finally:
        src.stop(2.0)


def test_the_drain_emits_each_topic_and_the_expired_frames(sessions):
    svc, cam = sessions
    src = EchoAtDrain(SourceContext(rig="t", session=svc))
    frames: list[StereoFrame] = []
    src.open()
    src.expire.append(make_frame(h=4, w=6).with_(seq=100))
    src.start(lambda f: frames.append(f) or True)
    try:
        time.sleep(0.3)
        put(cam, "a", b"1")
        put(cam, "b", b"2")
        assert wait_for(lambda: len(frames) == 3)
    finally:
        src.stop(2.0)
    assert frames[0].seq == 100 and sorted(f.seq for f in frames[1:]) == [1, 2]
    st = src.stats()
    assert st["emitted"] == 3 and st["received"] == 2


@pytest.mark.parametrize("how", ["request_stop", "stop"])
def test_stopping_wakes_the_idle_drain_at_once(sessions, how):
    """The drain sleeps up to ``poll_s`` (1 s here) on empty rings; a stop closes them and it ends at once."""
    svc, _ = sessions
    src = Echo(SourceContext(rig="t", session=svc), poll_s=1.0)
    src.open()
    src.start(lambda f: True)
    time.sleep(0.2)  # the drain is asleep in the rings' wait
    t0 = time.monotonic()
    if how == "request_stop":
        src.request_stop()
        assert src.finished.wait(2.0)
    else:
        src.stop(2.0)
    assert time.monotonic() - t0 < 0.5 and src.finished.is_set() and src.error is None
    src.close()


def test_stop_releases_a_callback_waiting_for_room_under_block(sessions):
    """Under ``block`` a full ring holds the callback; stop closes the rings, the wait ends and the drop is counted."""
    svc, cam = sessions
    src = Echo(SourceContext(rig="t", session=svc))
    src.input_policy = "block"
    src.open()
    time.sleep(0.3)
    for seq in range(3):  # the third waits for room in Zenoh's receive thread: nothing drains
        put(cam, "a", str(seq).encode())
    assert wait_for(lambda: src.stats()["received"] == 3)
    assert src.stats()["ring_dropped"] == 0
    t0 = time.monotonic()
    src.stop(2.0)
    assert time.monotonic() - t0 < 1.5
    assert wait_for(lambda: src.stats()["ring_dropped"] == 1)  # the waiting message dropped the oldest on close
