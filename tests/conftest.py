"""Shared fixtures: a free TCP port on 127.0.0.1 and Zenoh configs with multicast scouting off."""
from __future__ import annotations

import json
import socket
from typing import Callable, Sequence

import pytest


def free_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def zenoh_test_config(listen: Sequence[str] = (), connect: Sequence[str] = (), mode: str = "peer"):
    """A ``zenoh.Config`` for tests: explicit endpoints on 127.0.0.1, multicast scouting OFF."""
    import zenoh

    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(mode))
    conf.insert_json5("listen/endpoints", json.dumps(list(listen)))
    conf.insert_json5("connect/endpoints", json.dumps(list(connect)))
    conf.insert_json5("scouting/multicast/enabled", "false")
    return conf


@pytest.fixture
def tcp_port() -> int:
    """A free TCP port on 127.0.0.1."""
    return free_port()


@pytest.fixture
def zenoh_endpoint(tcp_port: int) -> str:
    """``tcp/127.0.0.1:<free port>``."""
    return f"tcp/127.0.0.1:{tcp_port}"


@pytest.fixture
def zenoh_config() -> Callable[..., object]:
    """Builder ``zenoh_config(listen=[...], connect=[...], mode="peer")`` -> ``zenoh.Config``."""
    return zenoh_test_config


@pytest.fixture(params=["portable", "avx2"])
def build(request, monkeypatch):
    """Run the test on each build of the VPP sweep kernel this machine can execute."""
    from helpers.vpp import BUILDS
    from vpp_service.vpp import backend

    mod = BUILDS[request.param]
    if mod is None:
        pytest.skip("no AVX2 build for this CPU / platform")
    monkeypatch.setattr(backend, "sweep", mod)
    return mod
