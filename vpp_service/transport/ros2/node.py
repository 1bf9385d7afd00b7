"""A ROS 2 node on a Zenoh session, as ``rmw_zenoh`` declares one: tokens, subscribers, publishers.

:class:`RosNode` declares the node's liveliness token, and for every subscriber and
publisher the data key expression plus its own token, so ``ros2 node list`` /
``ros2 topic list`` show it and lazy publishers (stereo_image_proc, most camera
drivers) start sending. :class:`RosPublisher` puts CDR payloads with the attachment
(sequence number from 1, system-time timestamp, 16-byte gid) in the chosen layout.

The node's ``distro`` picks the type-hash segment of its publishers' keys and of every
token (Humble: ``TypeHashNotSupported``, later distros: RIHS01). Subscribers listen on
``<domain>/<topic>/<type>/*``: any type hash is accepted; the type name must match.

Publishers follow rmw_zenoh's ``PublisherData::make``: Zenoh reliability from the QoS
reliability, congestion control BLOCK only for reliable + keep all (else DROP). A
publisher's gid is rmw_zenoh's (:func:`~vpp_service.transport.ros2.keys.entity_gid` of its
token). :attr:`RosPublisher.live` says whether a ROS subscriber would receive its samples:
a subscriber token for the same topic, type and hash on the graph (:class:`SubscriberGraph`).

Node ids come from one process-wide counter, so several nodes (e.g. the ros2 source
and the ros2 sink) can share one session with distinct ids.
"""

from __future__ import annotations

import contextlib
import itertools
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING

from vpp_service.transport.ros2 import attachment
from vpp_service.transport.ros2.graph import SubscriberGraph
from vpp_service.transport.ros2.keys import (
    DEFAULT_PUBLISHER,
    SENSOR_DATA,
    NodeName,
    Qos,
    check_distro,
    dds_type,
    entity_gid,
    entity_token,
    node_token,
    topic_key,
    type_hash,
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
        16-byte publisher id, rmw_zenoh's rule: XXH3-128 of ``token_key`` (:func:`entity_gid`).
    sequence_number : int
        Sequence number of the last sample put (0 before the first).
    """

    def __init__(
        self,
        publisher: zenoh.Publisher,
        token: zenoh.LivelinessToken,
        topic: str,
        key: str,
        token_key: str,
        *,
        graph: SubscriberGraph,
        ros_type: str,
        hash_: str,
    ) -> None:
        self._pub = publisher
        self._token = token
        self._graph = graph
        self.topic = topic
        self.key = key
        self.token_key = token_key
        self.gid = entity_gid(token_key)
        self.sequence_number = 0
        self._lock = threading.Lock()
        self._dds_type = dds_type(ros_type)
        self._type_hash = hash_

    @property
    def matching(self) -> bool:
        """True when any Zenoh subscriber matches the data key (also wildcard captures such as ``0/**``)."""
        status: object = self._pub.matching_status
        return bool(getattr(status, "matching", status))

    @property
    def live(self) -> bool:
        """True when a ROS subscriber token for this topic, type and type hash is on the graph.

        rmw_zenoh's graph is made of tokens: a lazy ROS publisher starts for a subscriber token, not for
        a plain Zenoh subscriber. A subscriber keyed with another hash (a Humble subscriber of a Jazzy
        publisher) would not receive the samples and does not count.
        """
        return self._graph.count(self.topic, self._dds_type, self._type_hash) > 0

    def other_hashes(self) -> list[str]:
        """Type hashes of ROS subscriber tokens for this topic and type keyed unlike this publisher.

        Such a subscriber (e.g. Humble's ``TypeHashNotSupported`` next to a Jazzy publisher) listens
        on another data key and receives nothing from this publisher.
        """
        mine = (self.topic, self._dds_type)
        return sorted(h for (topic, dds, h) in self._graph.topics() if (topic, dds) == mine and h != self._type_hash)

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
    distro : {"humble", "jazzy", "kilted", "rolling"}
        Whose rmw_zenoh the keys and tokens follow (the type-hash segment).
    """

    def __init__(
        self,
        session: zenoh.Session,
        domain_id: int,
        namespace: str,
        name: str,
        *,
        enclave: str = "",
        distro: str = "jazzy",
    ) -> None:
        self._session = session
        self.distro = check_distro(distro)
        self.name = NodeName(domain_id, str(session.zid()), _next_id(), namespace, name, enclave)
        self._tokens: list[zenoh.LivelinessToken] = []
        self._subs: list[zenoh.Subscriber[None] | zenoh.ext.AdvancedSubscriber[None]] = []
        self._pubs: list[RosPublisher] = []
        self._graph: SubscriberGraph | None = None

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

        The token declares ``qos`` and the node's distro's type hash. A transient-local ``qos``
        (``durability`` 1) also fetches what the topic's publishers cached before we came, as
        rmw_zenoh's subscriptions do (``SubscriptionData::init``): an advanced subscriber with
        history (late publishers detected, at most ``depth`` samples each) that publishers can
        detect. The callback runs on a Zenoh thread: it must only hand the sample over.
        """
        key = topic_key(self.name.domain_id, topic, ros_type, "*")
        if qos.durability == 1:
            import zenoh.ext

            history = zenoh.ext.HistoryConfig(detect_late_publishers=True, max_samples=qos.depth or None)
            self._subs.append(
                zenoh.ext.declare_advanced_subscriber(
                    self._session, key, callback, history=history, subscriber_detection=True
                )
            )
        else:
            self._subs.append(self._session.declare_subscriber(key, callback))
        hash_ = type_hash(ros_type, self.distro)
        tok = entity_token(self.name, _next_id(), "MS", topic, ros_type, qos=qos, hash_=hash_)
        self._tokens.append(self._session.liveliness().declare_token(tok))
        return key

    def publisher(
        self,
        topic: str,
        ros_type: str,
        qos: Qos = DEFAULT_PUBLISHER,
        *,
        low_priority: bool = False,
        hash_: str | None = None,
    ) -> RosPublisher:
        """Declare a publisher of a fully-qualified topic with its token.

        As rmw_zenoh: Zenoh reliability RELIABLE or BEST_EFFORT from ``qos.reliability``; congestion
        control BLOCK for reliable + keep all (never silently lost), else DROP (gives way under load).
        ``low_priority``: Zenoh priority DATA_LOW (visualisation images). ``hash_``: the type's RIHS01
        hash when it is not one of the four built-in types (e.g. from a bag's type store); default: the
        node's distro's hash segment.
        """
        import zenoh

        if qos.durability == 1:
            raise ValueError("transient-local publishers are not supported (no publisher cache)")
        hash_ = hash_ or type_hash(ros_type, self.distro)
        key = topic_key(self.name.domain_id, topic, ros_type, hash_)
        reliable = qos.reliability == 1
        pub = self._session.declare_publisher(
            key,
            congestion_control=zenoh.CongestionControl.BLOCK
            if reliable and qos.history == 2
            else zenoh.CongestionControl.DROP,
            reliability=zenoh.Reliability.RELIABLE if reliable else zenoh.Reliability.BEST_EFFORT,
            priority=zenoh.Priority.DATA_LOW if low_priority else zenoh.Priority.DATA,
        )
        tok_key = entity_token(self.name, _next_id(), "MP", topic, ros_type, qos=qos, hash_=hash_)
        tok = self._session.liveliness().declare_token(tok_key)
        rp = RosPublisher(pub, tok, topic, key, tok_key, graph=self._subscriber_graph(), ros_type=ros_type, hash_=hash_)
        self._pubs.append(rp)
        return rp

    def _subscriber_graph(self) -> SubscriberGraph:
        """The domain's subscriber tokens, watched from the first publisher on."""
        if self._graph is None:
            self._graph = SubscriberGraph(self._session, self.name.domain_id)
        return self._graph

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
        if self._graph is not None:
            self._graph.close()
            self._graph = None
        self._pubs.clear()
        self._subs.clear()
        self._tokens.clear()


__all__ = ["RosNode", "RosPublisher"]
