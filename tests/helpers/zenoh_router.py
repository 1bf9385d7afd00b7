"""A Zenoh router in its own process on 127.0.0.1, for tests that kill it (SIGKILL) and start it again."""

from __future__ import annotations

import subprocess
import sys
import threading

#: The router process: a session in router mode on ``argv[1:]``, multicast scouting off; prints "ready" once open.
ROUTER_CODE = (
    "import json, sys, time, zenoh\n"
    "c = zenoh.Config()\n"
    "c.insert_json5('mode', '\"router\"')\n"
    "c.insert_json5('listen/endpoints', json.dumps(sys.argv[1:]))\n"
    "c.insert_json5('scouting/multicast/enabled', 'false')\n"
    "s = zenoh.open(c)\n"
    "print('ready', flush=True)\n"
    "while True:\n"
    "    time.sleep(3600)\n"
)


class RouterProcess:
    """``RouterProcess("tcp/127.0.0.1:PORT")``: :meth:`start` (returns once it listens), :meth:`kill`.

    Use as a context manager to be sure it is killed.
    """

    def __init__(self, endpoint: str, *more: str) -> None:
        self.endpoint = endpoint
        self.more = more  # further listen endpoints
        self.proc: subprocess.Popen[str] | None = None

    def start(self, timeout: float = 30.0) -> None:
        """Start the router; return once its session is open.

        Raises
        ------
        RuntimeError
            It did not report ready within ``timeout`` seconds.
        """
        proc = subprocess.Popen(
            [sys.executable, "-c", ROUTER_CODE, self.endpoint, *self.more], stdout=subprocess.PIPE, text=True
        )
        self.proc = proc
        lines: list[str] = []
        reader = threading.Thread(target=lambda: lines.append(proc.stdout.readline() if proc.stdout else ""))
        reader.daemon = True
        reader.start()
        reader.join(timeout)
        if not lines or lines[0].strip() != "ready":
            self.kill()
            raise RuntimeError(f"the Zenoh router on {self.endpoint} did not start")

    def kill(self) -> None:
        """SIGKILL the router (if running) and reap it."""
        if self.proc is None:
            return
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait()
        if self.proc.stdout is not None:
            self.proc.stdout.close()

    def __enter__(self) -> RouterProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.kill()
