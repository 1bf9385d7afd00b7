"""A ROS 2 node on a Zenoh session, as ``rmw_zenoh`` declares one: tokens, subscribers, publishers.

:class:`RosNode` declares the node's liveliness token, and for every subscriber and
publisher the data key expression plus its own token, so ``ros2 node list`` /
``ros2 topic list`` show it and lazy publishers (stereo_image_proc, most camera
drivers) start sending. :class:`RosPublisher` puts CDR payloads with the attachment
(sequence number from 1, system-time timestamp, 16-byte gid) in the chosen layout.

Subscribers listen on ``<domain>/<topic>/<type>/*``: any type hash is accepted
(Humble publishers send ``TypeHashNotSupported``); the type name must match.

Node ids come from one process-wide counter, so several nodes (e.g. the ros2 source
and the ros2 sink) can share one session with distinct ids.
"""

from __future__ import annotations

import contextlib
import hashlib
import itertools
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING

from vpp_service.transport.ros2 import attachment
from vpp_service.transport.ros2.keys import (
    DEFAULT_PUBLISHER,
    SENSOR_DATA,
    NodeName,
    Qos,
    entity_token,
    node_token,
    topic_key,
)

if TYPE_CHECKING:
    import zenoh

_IDS = itertools.count()
_IDS_LOCK = threading.Lock()


def _next_id() -> int:
    with _IDS_LOCK:
        return next(_IDS)


class RosPublisher:
    """One topic's publisher: a Zenoh publisher plus its liveliness token and attachment state.

    Attributes
    ----------
    topic : str
        Fully-qualified topic name.
    key : str
        Data key expression.
    token_key : str
        Liveliness key of the publisher.
    gid : bytes
        16-byte publisher id (BLAKE2b-128 of ``token_key``: unique per publisher).
    sequence_number : int
        Sequence number of the last sample put (0 before the first).
    """

    def __init__(
        self, publisher: zenoh.Publisher, token: zenoh.LivelinessToken, topic: str, key: str, token_key: str
    ) -> None:
        self._pub = publisher
        self._token = token
        self.topic = topic
        self.key = key
        self.token_key = token_key
        self.gid = hashlib.blake2b(token_key.encode(), digest_size=attachment.GID_SIZE).digest()
        self.sequence_number = 0
        self._lock = threading.Lock()

    @property
    def matching(self) -> bool:
        """True when some Zenoh subscriber matches the data key (a ROS subscriber declares one)."""
        status: object = self._pub.matching_status
        return bool(getattr(status, "matching", status))

    def put(self, payload: bytes | bytearray, layout: attachment.Layout = "current") -> int:
        """Publish one CDR payload with its attachment; returns its sequence number."""
        with self._lock:
            self.sequence_number += 1
            seq = self.sequence_number
        att = attachment.encode(attachment.Attachment(seq, time.time_ns(), self.gid), layout)
        self._pub.put(payload, attachment=att)
        return seq

    def undeclare(self) -> None:
        """Undeclare the token and the publisher (no-op once the session is closed)."""
        for entity in (self._token, self._pub):
            # the session may already be closed: nothing left to release then
            with contextlib.suppress(Exception):
                entity.undeclare()


class RosNode:
    """A node on ``session``: its token, and subscribers/publishers with theirs.

    Parameters
    ----------
    session : zenoh.Session
        An open session (owned by the caller).
    domain_id : int
        ROS domain id.
    namespace : str
        Node namespace, e.g. ``/stereo``.
    name : str
        Node name (one token).
    enclave : str
        Security enclave (empty = none).
    """

    def __init__(self, session: zenoh.Session, domain_id: int, namespace: str, name: str, enclave: str = "") -> None:
        self._session = session
        self.name = NodeName(domain_id, str(session.zid()), _next_id(), namespace, name, enclave)
        self._tokens: list[zenoh.LivelinessToken] = []
        self._subs: list[zenoh.Subscriber[None]] = []
        self._pubs: list[RosPublisher] = []

    @property
    def token_key(self) -> str:
        """Liveliness key of the node."""
        return node_token(self.name)

    def open(self) -> None:
        """Declare the node's token."""
        self._tokens.append(self._session.liveliness().declare_token(self.token_key))

    def subscribe(
        self, topic: str, ros_type: str, callback: Callable[[zenoh.Sample], None], qos: Qos = SENSOR_DATA
    ) -> str:
        """Subscribe ``callback`` to a fully-qualified topic (any type hash); returns the data key.

        The callback runs on a Zenoh thread: it must only hand the sample over.
        """
        key = topic_key(self.name.domain_id, topic, ros_type, "*")
        self._subs.append(self._session.declare_subscriber(key, callback))
        tok = entity_token(self.name, _next_id(), "MS", topic, ros_type, qos=qos)
        self._tokens.append(self._session.liveliness().declare_token(tok))
        return key

    def publisher(
        self, topic: str, ros_type: str, qos: Qos = DEFAULT_PUBLISHER, *, block: bool = True, hash_: str | None = None
    ) -> RosPublisher:
        """Declare a publisher of a fully-qualified topic with its token.

        ``block``: congestion control BLOCK (the product: never silently lost) or DROP
        (visualisation images: give way under load). ``hash_``: the type's RIHS01 hash when
        it is not one of the four built-in types (e.g. from a bag's type store).
        """
        import zenoh

        key = topic_key(self.name.domain_id, topic, ros_type, hash_)
        pub = self._session.declare_publisher(
            key,
            congestion_control=zenoh.CongestionControl.BLOCK if block else zenoh.CongestionControl.DROP,
            priority=zenoh.Priority.DATA if block else zenoh.Priority.DATA_LOW,
        )
        tok_key = entity_token(self.name, _next_id(), "MP", topic, ros_type, qos=qos, hash_=hash_)
        tok = self._session.liveliness().declare_token(tok_key)
        rp = RosPublisher(pub, tok, topic, key, tok_key)
        self._pubs.append(rp)
        return rp

    def close(self) -> None:
        """Undeclare every subscriber, publisher and token (no-op once the session is closed)."""
        for p in self._pubs:
            p.undeclare()
        # the session may already be closed: nothing left to release then
        for sub in self._subs:
            with contextlib.suppress(Exception):
                sub.undeclare()
        for tok in self._tokens:
            with contextlib.suppress(Exception):
                tok.undeclare()
        self._pubs.clear()
        self._subs.clear()
        self._tokens.clear()


__all__ = ["RosNode", "RosPublisher"]
