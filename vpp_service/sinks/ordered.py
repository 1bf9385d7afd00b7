"""Writes in ``seq`` order for the sinks that need it (``files``, ``record``, ``rerun``).

In a rig's worker pool (:mod:`vpp_service.service.pool`) a worker that takes
over a dead member's frames processes them after newer ones of its own share,
so its results reach the sinks out of order. :class:`OrderedWrites` passes a
sink's results through a :class:`~vpp_service.transport.reorder.ReorderBuffer`
(``reorder_window`` results held at most ``reorder_wait_ms`` for a hole to fill)
and counts what it could not put in order: ``order_gaps`` (frames of this
worker that never came), ``order_late`` (written out of order),
``order_duplicates`` (dropped). In a pool, other workers' frames are never a
gap (the service passes ``context.extra["seq_expected"]``). Only a pool
worker's sinks reorder (``reorder_window``, default 16; 0 = off): a single
service's pipeline delivers results in order anyway.

A result held for a hole is written by a later write, or at the latest when the sink closes.
"""

from __future__ import annotations

from collections.abc import Callable

from vpp_service.frame import FusionResult
from vpp_service.plugin import PluginContext
from vpp_service.transport.reorder import ReorderBuffer


def check_reorder_options(window: int, wait_ms: float) -> None:
    """Validate ``reorder_window`` (an int in [0, 1024]) and ``reorder_wait_ms`` ((0, 60000]).

    Raises
    ------
    ValueError
        Naming the option.
    """
    if isinstance(window, bool) or not isinstance(window, int) or not 0 <= window <= 1024:
        raise ValueError(f"reorder_window: must be an int in [0, 1024] (0 = off), got {window!r}")
    if isinstance(wait_ms, bool) or not isinstance(wait_ms, (int, float)) or not 0 < wait_ms <= 60000:
        raise ValueError(f"reorder_wait_ms: must be a number in (0, 60000], got {wait_ms!r}")


class OrderedWrites:
    """Hand a sink's results to ``deliver`` in ``seq`` order (see the module docstring).

    Parameters
    ----------
    window : int
        ``reorder_window``: results held at most; 0 = off. Used only in a pool.
    wait_ms : float
        ``reorder_wait_ms``.
    context : PluginContext
        The sink's context (``extra["seq_expected"]`` in a pool).
    deliver : callable
        Writes one result.
    """

    def __init__(
        self, window: int, wait_ms: float, context: PluginContext, deliver: Callable[[FusionResult], None]
    ) -> None:
        expected = context.extra.get("seq_expected")
        self.deliver = deliver
        self.buffer: ReorderBuffer[FusionResult] | None = None
        if window > 0 and callable(expected):  # a pool worker's sink
            self.buffer = ReorderBuffer(window, wait_ms / 1e3, expected)

    @property
    def enabled(self) -> bool:
        """Whether results are reordered."""
        return self.buffer is not None

    def write(self, result: FusionResult) -> None:
        """Deliver ``result`` now, or when the results before it came (or their wait expired)."""
        if self.buffer is None:
            self.deliver(result)
            return
        for _, r in self.buffer.push(int(result.frame.seq), result):
            self.deliver(r)

    def flush(self) -> None:
        """Deliver everything held (the sink is closing)."""
        if self.buffer is not None:
            for _, r in self.buffer.flush():
                self.deliver(r)

    def stats(self) -> dict[str, int]:
        """``order_*`` counters (none when off)."""
        if self.buffer is None:
            return {}
        st = self.buffer.stats()
        return {
            "order_held": st["held"],
            "order_reordered": st["reordered"],
            "order_gaps": st["gaps"],
            "order_late": st["late"],
            "order_duplicates": st["duplicates"],
        }


__all__ = ["OrderedWrites", "check_reorder_options"]
