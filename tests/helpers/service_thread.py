"""A service run in a background thread of the test process (real Zenoh on loopback, real pipeline)."""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Iterator, Mapping
from typing import Any

from vpp_service.service.app import ServiceSummary, run_service
from vpp_service.service.config import validate_config


@contextlib.contextmanager
def service_in_thread(data: Mapping[str, Any]) -> Iterator[tuple[threading.Thread, dict[str, ServiceSummary]]]:
    """Run ``run_service`` on the config mapping ``data``; stop it (bounded) when the block ends.

    Yields the thread and a dict that receives the final status under ``"status"``.
    """
    cfg = validate_config(data)
    stop = threading.Event()
    result: dict[str, ServiceSummary] = {}

    def target() -> None:
        result["status"] = run_service(cfg, stop, stream=None)

    thread = threading.Thread(target=target, daemon=True)
    thread.start()
    try:
        yield thread, result
    finally:
        stop.set()
        thread.join(15.0)
