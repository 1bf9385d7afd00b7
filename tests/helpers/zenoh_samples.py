"""Receiving Zenoh samples in tests."""
from __future__ import annotations

import time

import zenoh


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
