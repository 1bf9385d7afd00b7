"""What every network source does: subscribe, bound, drain, count.

A network source (:mod:`~vpp_service.sources.zenoh`, :mod:`~vpp_service.sources.ros2`)
takes messages from subscriber callbacks on Zenoh's receive thread and turns them
into frames on its own thread. :class:`NetworkSource` holds the part they share:

- **The callback** (:meth:`NetworkSource._on_sample`): the cheap checks, then the
  message into its topic's ring (:class:`~vpp_service.queueing.ReceiveRings`). A
  message over ``max_message_bytes`` is refused by its length, before its payload is
  copied out of Zenoh; the subclass's :meth:`~NetworkSource._admit` makes its own
  checks and builds what the ring holds. A refusal (:class:`Refused`) is counted in
  ``rejected`` and by cause (:meth:`NetworkSource.refused_by`), reported through
  ``reject`` and never takes a ring slot, so junk cannot displace valid messages.
  Under the pipeline's ``latest`` input policy a full ring drops its oldest message
  (``ring_dropped``, the ``source_ring`` loss); under ``block`` the callback waits
  for room, holding the link back.
- **The drain loop** (:meth:`NetworkSource.run`): take from each topic's ring in
  turn, hand each message to the subclass's :meth:`~NetworkSource._handle` and emit
  the frames it returns, then the frames :meth:`~NetworkSource._expire` releases;
  sleep until a message arrives (at most ``poll_s``) when the rings were empty.
- **Stopping**: :meth:`~NetworkSource.request_stop` and :meth:`~NetworkSource.stop`
  close the rings, which wakes the drain loop and every callback waiting for room.

Where ``received`` is counted is the subclass's choice (:attr:`NetworkSource.received_at`).
"""

from __future__ import annotations

import time
from abc import abstractmethod
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Any, ClassVar, Generic, Literal, TypeVar

from vpp_service.frame import StereoFrame
from vpp_service.queueing import ReceiveRings
from vpp_service.sources.base import Emit, Reject, Source, SourceContext

if TYPE_CHECKING:
    import zenoh

#: What a ring holds (a decoded message, or the sample itself).
T = TypeVar("T")

#: Prefix of the counters of the callback's refusals by cause.
_REFUSED = "rejected."


class Refused(Exception):
    """A message the subscriber callback turns away.

    Parameters
    ----------
    cause : str
        Short cause, the name it is counted under (``"too_large"``, ``"attachment"``, ...).
    text : str
        What is wrong, reported after the topic's name.
    """

    def __init__(self, cause: str, text: str) -> None:
        super().__init__(text)
        self.cause = cause
        self.text = text


class NetworkSource(Source, Generic[T]):
    """Base class of the sources fed by network subscriber callbacks (see the module docstring).

    A subclass opens its subscribers in :meth:`open` (after :meth:`open_rings`),
    each calling ``self._on_sample(topic, sample)``, and implements :meth:`_admit`,
    :meth:`_handle` and :meth:`_topic_name`.

    Parameters
    ----------
    options : object
        The subclass's options.
    context : SourceContext
        Service-wide facts (``context.session`` is the Zenoh session).
    max_message_bytes : int
        Largest message accepted; a larger one is refused by its length in the callback.
    poll_s : float
        Longest idle sleep of the drain loop between checks for a stop request.
    """

    needs_session = True
    network = True  # a live camera on the network: a service that resumes after a restart
    #: Where ``received`` is counted: ``"arrival"``, every message the callback gets (those a ring drops
    #: included); ``"drain"``, every message refused by the callback or taken from a ring (a message a
    #: ring drops is counted in ``ring_dropped`` only).
    received_at: ClassVar[Literal["arrival", "drain"]] = "arrival"

    def __init__(self, options: object, context: SourceContext, *, max_message_bytes: int, poll_s: float) -> None:
        super().__init__(options, context)
        self.max_message_bytes = max_message_bytes
        self.poll_s = poll_s
        self._rings: ReceiveRings[T] | None = None  # one ring per topic, built at open
        self._reject: Reject | None = None
        self._counters["received"] = 0

    def session(self, name: str) -> zenoh.Session:
        """The service's Zenoh session; ValueError naming ``source.<name>`` when there is none."""
        session: zenoh.Session | None = self.context.session
        if session is None:
            raise ValueError(f"source.{name}: needs an open zenoh session (service.zenoh section)")
        return session

    def open_rings(self, sizes: dict[str, int]) -> ReceiveRings[T]:
        """Build the receive rings (one per topic, under the input policy); call before subscribing."""
        self._rings = ReceiveRings(sizes, self.input_policy)
        return self._rings

    @property
    def ring_dropped(self) -> int:
        """Messages the rings dropped (``latest``, or a callback still waiting when the source stopped)."""
        return self._rings.dropped_total if self._rings is not None else 0

    def start(self, emit: Emit, reject: Reject | None = None, on_finished: Callable[[], None] | None = None) -> None:
        """Start the drain thread; ``reject`` also hears of the messages the subscriber callback turns away."""
        self._reject = reject
        super().start(emit, reject, on_finished)

    def _on_sample(self, topic: str, sample: zenoh.Sample) -> None:
        """Subscriber callback: the cheap checks, then the message into ``topic``'s ring.

        Runs on Zenoh's receive thread; under the ``block`` input policy a full ring
        makes it wait for room (back-pressure through Zenoh); under ``latest`` it never
        waits (the oldest message is dropped and counted).
        """
        recv_ns = time.monotonic_ns()  # for durations (latency): a monotonic clock, immune to clock steps
        if self.received_at == "arrival":
            self.count("received")
        try:
            size = len(sample.payload)
            if size > self.max_message_bytes:  # by its length, before the payload is copied out of Zenoh
                raise self._too_large(size)
            item = self._admit(topic, sample, recv_ns)
        except Refused as exc:
            if self.received_at == "drain":
                self.count("received")
            self.count("rejected")
            self.count(_REFUSED + exc.cause)
            if self._reject is not None:
                self._reject(f"{self._topic_name(topic, sample)}: {exc.text}")
            return
        assert self._rings is not None  # subscribed only after open built them
        self._rings.put(topic, item)

    def _too_large(self, size: int) -> Refused:
        """The refusal of a message of ``size`` bytes, over ``max_message_bytes``."""
        return Refused("too_large", f"too_large: {size} bytes > max {self.max_message_bytes}")

    @abstractmethod
    def _admit(self, topic: str, sample: zenoh.Sample, recv_ns: int) -> T:
        """The subclass's checks in the callback: what goes into the ring, or :class:`Refused`.

        Parameters
        ----------
        topic : str
            The ring the message is for.
        sample : zenoh.Sample
            The message, already within ``max_message_bytes``.
        recv_ns : int
            ``time.monotonic_ns()`` when the callback got it.
        """

    @abstractmethod
    def _topic_name(self, topic: str, sample: zenoh.Sample) -> str:
        """The name a refusal of ``sample`` on ``topic`` is reported under (a key expression, a ROS topic)."""

    def _begin(self, reject: Reject) -> None:
        """Called on the drain thread before the first message; nothing by default."""

    @abstractmethod
    def _handle(self, topic: str, item: T, reject: Reject) -> Iterable[StereoFrame]:
        """Turn one message taken from ``topic``'s ring into the frames it completes (often none or one)."""

    def _expire(self) -> Iterable[StereoFrame]:
        """Frames released by time rather than by a message, checked every turn of the loop; none by default."""
        return ()

    def run(self, emit: Emit, reject: Reject) -> None:
        """Drain the rings, hand each message to :meth:`_handle` and emit its frames, until stopped."""
        rings = self._rings
        assert rings is not None  # run after open
        self._begin(reject)
        while not self.stopping():
            got = False
            for topic in rings.keys:
                item = rings.take(topic)
                if item is None:
                    continue
                got = True
                if self.received_at == "drain":
                    self.count("received")
                for frame in self._handle(topic, item, reject):
                    self.count("emitted")
                    emit(frame)
            for frame in self._expire():
                self.count("emitted")
                emit(frame)
            if not got:
                rings.wait(self.poll_s)

    def request_stop(self) -> None:
        """Ask the drain thread to stop and wake it, and every callback waiting for room (safe from any thread)."""
        super().request_stop()
        if self._rings is not None:
            self._rings.close()

    def stop(self, timeout: float = 5.0) -> None:
        """Wake the drain thread and the callbacks, stop within ``timeout`` seconds and :meth:`close`."""
        if self._rings is not None:
            self._rings.close()
        super().stop(timeout)

    def refused_by(self) -> dict[str, int]:
        """Messages the callback refused, by cause (their sum is part of ``rejected``)."""
        with self._counters_lock:
            return {k.removeprefix(_REFUSED): v for k, v in self._counters.items() if k.startswith(_REFUSED)}

    def stats(self) -> dict[str, Any]:
        """The counters (``received``, ``emitted``, ``rejected`` and the subclass's) and ``ring_dropped``."""
        out: dict[str, Any] = {k: v for k, v in super().stats().items() if not k.startswith(_REFUSED)}
        out["ring_dropped"] = self.ring_dropped
        return out

    def losses(self) -> dict[str, int]:
        """Valid messages lost in this source, by cause: here the rings' (``source_ring``)."""
        return {"source_ring": self.ring_dropped}


__all__ = ["NetworkSource", "Refused"]
