"""The one error type of the ROS 2 transport: a rejected message with a named cause."""

from __future__ import annotations


class Ros2Error(ValueError):
    """A ROS 2 message (payload, attachment, key) that is refused.

    Parameters
    ----------
    reason : str
        Short cause used as a counter name (``"too_large"``, ``"cdr"``, ``"encoding"``, ...).
    detail : str
        Human-readable explanation.
    """

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(f"{reason}: {detail}")
        self.reason = reason
        self.detail = detail


__all__ = ["Ros2Error"]
