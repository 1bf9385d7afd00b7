"""A real in-memory sink for pipeline tests."""

from __future__ import annotations

from vpp_service.frame import FusionResult
from vpp_service.sinks.base import Sink, SinkContext


class CollectSink(Sink):
    """A real Sink implementation that keeps every result it is given (``written`` counts them)."""

    Options = None

    def __init__(self) -> None:
        super().__init__(None, SinkContext())
        self.results: list[FusionResult] = []
        self.closed = False

    def write(self, result: FusionResult) -> None:
        self.results.append(result)
        self._counters["written"] += 1

    def close(self, timeout: float = 5.0) -> None:
        self.closed = True
