"""Shared fixtures: a free TCP port on 127.0.0.1, Zenoh configs with multicast scouting off, a umask."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING

import pytest

from helpers.zenoh_loopback import free_port, zenoh_test_config

if TYPE_CHECKING:
    import zenoh


@pytest.fixture
def tcp_port() -> int:
    """A free TCP port on 127.0.0.1."""
    return free_port()


@pytest.fixture
def zenoh_endpoint(tcp_port: int) -> str:
    """``tcp/127.0.0.1:<free port>``."""
    return f"tcp/127.0.0.1:{tcp_port}"


@pytest.fixture
def zenoh_config() -> Callable[..., zenoh.Config]:
    """Builder ``zenoh_config(listen=[...], connect=[...], mode="peer")`` -> ``zenoh.Config``."""
    return zenoh_test_config


@pytest.fixture(params=[0o022, 0o027], ids=["umask022", "umask027"])
def umask(request: pytest.FixtureRequest) -> Iterator[int]:
    """Run the test under this process umask (restored afterwards)."""
    old = os.umask(request.param)
    try:
        yield request.param
    finally:
        os.umask(old)


def _use_build(name: str, builds: dict, module: object, attr: str, monkeypatch: pytest.MonkeyPatch):
    """Point ``module.attr`` at the kernel build ``builds[name]`` for one test (skip where it cannot run)."""
    mod = builds[name]
    if mod is None:
        pytest.skip("no AVX2 build for this CPU / platform")
    monkeypatch.setattr(module, attr, mod)
    return mod


@pytest.fixture(params=["portable", "avx2"])
def build(request, monkeypatch):
    """Run the test on each build of the VPP sweep kernel this machine can execute."""
    from helpers.vpp import BUILDS
    from vpp_service.vpp import backend

    return _use_build(request.param, BUILDS, backend, "sweep", monkeypatch)


@pytest.fixture(params=["portable", "avx2"])
def census_build(request, monkeypatch):
    """Run the test on each build of the Census-SGM kernels this machine can execute."""
    from helpers.census_sgm_reference import CENSUS_BUILDS
    from vpp_service.matchers import census_sgm

    return _use_build(request.param, CENSUS_BUILDS, census_sgm, "_k", monkeypatch)


@pytest.fixture
def sessions(zenoh_endpoint: str) -> Iterator[tuple[zenoh.Session, zenoh.Session]]:
    """Two Zenoh sessions on loopback: ``(listener, peer)`` (the service's and a camera's or client's)."""
    import zenoh

    with (
        zenoh.open(zenoh_test_config(listen=[zenoh_endpoint])) as listener,
        zenoh.open(zenoh_test_config(connect=[zenoh_endpoint])) as peer,
    ):
        yield listener, peer
