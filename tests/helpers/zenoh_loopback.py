"""Zenoh on loopback for tests.

Free ports, configs with explicit 127.0.0.1 endpoints and multicast scouting off, receiving samples.
"""

from __future__ import annotations

import json
import socket
import time
from collections.abc import Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import zenoh


def free_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def zenoh_test_config(listen: Sequence[str] = (), connect: Sequence[str] = (), mode: str = "peer") -> zenoh.Config:
    """A ``zenoh.Config`` for tests: explicit endpoints on 127.0.0.1, multicast scouting OFF."""
    import zenoh

    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(mode))
    conf.insert_json5("listen/endpoints", json.dumps(list(listen)))
    conf.insert_json5("connect/endpoints", json.dumps(list(connect)))
    conf.insert_json5("scouting/multicast/enabled", "false")
    return conf


def collect(sub: zenoh.Subscriber, n: int, timeout: float = 5.0) -> list[zenoh.Sample]:
    """Up to ``n`` samples from a FIFO-channel subscriber, waiting at most ``timeout`` seconds.

    The samples are kept (and with them any shared-memory buffers they pin).
    """
    out: list[zenoh.Sample] = []
    deadline = time.monotonic() + timeout
    while len(out) < n and time.monotonic() < deadline:
        s = sub.try_recv()
        if s is None:
            time.sleep(0.01)
        else:
            out.append(s)
    return out
