"""The subscribers on a ROS 2 domain as ``rmw_zenoh``'s graph knows them: by their liveliness tokens.

rmw_zenoh builds its graph (``GraphCache``) from liveliness tokens alone: a liveliness
subscriber on ``@ros2_lv/<domain>/**`` with history reports every token alive (PUT) and
every token gone (DELETE). A ROS publisher's ``get_subscription_count`` counts subscriber
tokens, not Zenoh subscribers, so a wildcard capture (``zenoh sub '0/**'``) is no subscriber.
:class:`SubscriberGraph` keeps the same view, restricted to subscriber (``MS``) tokens, counted
by topic, type and type hash.
"""

from __future__ import annotations

import contextlib
import threading
from collections import Counter
from typing import TYPE_CHECKING

from vpp_service.transport.ros2.keys import check_domain, parse_entity_token

if TYPE_CHECKING:
    import zenoh


class SubscriberGraph:
    """Live subscriber tokens of one domain, counted by ``(topic, dds type, type hash)``.

    Parameters
    ----------
    session : zenoh.Session
        An open session (owned by the caller).
    domain_id : int
        ROS domain id.
    """

    def __init__(self, session: zenoh.Session, domain_id: int) -> None:
        self.domain_id = check_domain(domain_id)
        self._lock = threading.Lock()
        self._tokens: dict[str, tuple[str, str, str]] = {}
        self._counts: Counter[tuple[str, str, str]] = Counter()
        # PUT = a token alive (history: those already declared too), DELETE = gone
        self._sub = session.liveliness().declare_subscriber(
            f"@ros2_lv/{self.domain_id}/*/*/*/MS/**", self._on_token, history=True
        )

    def _on_token(self, sample: zenoh.Sample) -> None:
        """Zenoh callback: count a subscriber token in or out (other tokens are ignored)."""
        import zenoh

        key = str(sample.key_expr)
        ent = parse_entity_token(key, self.domain_id)
        if ent is None or ent.kind != "MS":
            return
        topic = (ent.topic, ent.dds_type, ent.type_hash)
        with self._lock:
            if sample.kind == zenoh.SampleKind.PUT:
                if key not in self._tokens:
                    self._tokens[key] = topic
                    self._counts[topic] += 1
            elif self._tokens.pop(key, None) is not None:
                self._counts[topic] -= 1
                if self._counts[topic] <= 0:
                    del self._counts[topic]

    def count(self, topic: str, dds_type: str, type_hash: str) -> int:
        """Subscriber tokens alive for a fully-qualified ``topic`` of ``dds_type`` keyed with ``type_hash``."""
        with self._lock:
            return self._counts.get((topic, dds_type, type_hash), 0)

    def topics(self) -> dict[tuple[str, str, str], int]:
        """Every ``(topic, dds type, type hash)`` with live subscriber tokens, and how many."""
        with self._lock:
            return dict(self._counts)

    def close(self) -> None:
        """Stop watching (no-op once the session is closed)."""
        # the session may already be closed: nothing left to release then
        with contextlib.suppress(Exception):
            self._sub.undeclare()


__all__ = ["SubscriberGraph"]
