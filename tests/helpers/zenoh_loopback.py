"""Zenoh sessions for tests: explicit endpoints on 127.0.0.1, multicast scouting off."""

from __future__ import annotations

import json
import socket
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
