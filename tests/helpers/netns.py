"""Hosts on one machine: Linux network namespaces joined to this one by veth pairs (needs root and ``ip``).

``with NetnsHosts(2) as hosts``: ``hosts.names[k]`` is a namespace with its own
network stack, reachable only over its veth link; ``hosts.gateway[k]`` is this
namespace's address on that link (where a router listening on ``0.0.0.0``
answers). ``hosts.wrap(k, argv)`` runs ``argv`` inside namespace ``k``.
Everything is removed on exit.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from types import TracebackType


def netns_available() -> bool:
    """Whether this process may create network namespaces and veth links (root with ``ip``)."""
    if os.geteuid() != 0 or shutil.which("ip") is None:
        return False
    probe = f"vppprobe{os.getpid()}"
    ok = subprocess.run(["ip", "netns", "add", probe], capture_output=True, check=False).returncode == 0
    if ok:
        subprocess.run(["ip", "netns", "del", probe], capture_output=True, check=False)
    return ok


def _ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, text=True)


class NetnsHosts:
    """``n`` network namespaces, each on its own /30 link to this namespace (10.213.<k>.0/30)."""

    def __init__(self, n: int) -> None:
        tag = os.getpid() % 100000
        self.names = [f"vpphost{tag}-{k}" for k in range(n)]
        self._veths = [f"vpv{tag}h{k}" for k in range(n)]
        self.gateway = [f"10.213.{k}.1" for k in range(n)]
        self.address = [f"10.213.{k}.2" for k in range(n)]

    def __enter__(self) -> NetnsHosts:
        try:
            for k, ns in enumerate(self.names):
                outer, inner = self._veths[k], self._veths[k] + "i"
                _ip("netns", "add", ns)
                _ip("link", "add", outer, "type", "veth", "peer", "name", inner)
                _ip("link", "set", inner, "netns", ns)
                _ip("addr", "add", f"{self.gateway[k]}/30", "dev", outer)
                _ip("link", "set", outer, "up")
                _ip("-n", ns, "addr", "add", f"{self.address[k]}/30", "dev", inner)
                _ip("-n", ns, "link", "set", inner, "up")
                _ip("-n", ns, "link", "set", "lo", "up")
        except BaseException:
            self.close()
            raise
        return self

    def wrap(self, k: int, argv: list[str]) -> list[str]:
        """``argv`` run inside namespace ``k``."""
        return ["ip", "netns", "exec", self.names[k], *argv]

    def close(self) -> None:
        """Remove the links and the namespaces (what exists of them)."""
        for veth in self._veths:
            subprocess.run(["ip", "link", "del", veth], capture_output=True, check=False)
        for ns in self.names:
            subprocess.run(["ip", "netns", "del", ns], capture_output=True, check=False)

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()
