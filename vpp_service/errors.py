"""The error a command reports as a start-up failure (exit status 2) rather than a run-time one (exit 1)."""

from __future__ import annotations


class StartupError(RuntimeError):
    """Something outside the configuration keeps the service from starting (e.g. Zenoh cannot listen)."""


__all__ = ["StartupError"]
