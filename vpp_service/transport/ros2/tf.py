"""Static transforms (``/tf_static``) and the chain between two frames, as tf2 composes it.

:class:`StaticTransforms` keeps the latest transform received for each child frame
(a tf tree: one parent per frame) and :meth:`~StaticTransforms.lookup` composes the
4 x 4 transform taking a point from a source frame into a target frame through their
nearest common ancestor: ``T_target<-source = inv(T_a<-target) @ T_a<-source``. The
``ros2`` source uses it for the cloud: left optical frame <- ... <- the cloud's
``header.frame_id``.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from vpp_service.transport.ros2.messages import Transform

#: Longest parent chain followed (a longer one, or a loop, is refused).
MAX_DEPTH = 64


class StaticTransforms:
    """The static transform tree received so far (see the module docstring)."""

    def __init__(self) -> None:
        self._parent: dict[str, tuple[str, np.ndarray]] = {}

    def add(self, transforms: Iterable[Transform]) -> None:
        """Add or replace the transforms (the latest one per child frame wins, as in tf2)."""
        for t in transforms:
            self._parent[t.child] = (t.parent, t.matrix)

    def frames(self) -> list[str]:
        """Every frame known, sorted."""
        return sorted({*self._parent, *(p for p, _ in self._parent.values())})

    def _ancestors(self, frame: str) -> dict[str, np.ndarray]:
        """Each ancestor ``a`` of ``frame`` (itself included) with ``T_a<-frame``."""
        out = {frame: np.eye(4)}
        cur, acc = frame, np.eye(4)
        for _ in range(MAX_DEPTH):
            up = self._parent.get(cur)
            if up is None:
                return out
            cur, acc = up[0], up[1] @ acc
            if cur in out:
                raise LookupError(f"tf: frames form a loop at {cur!r}")
            out[cur] = acc
        raise LookupError(f"tf: chain from {frame!r} longer than {MAX_DEPTH} frames")

    def lookup(self, target: str, source: str) -> np.ndarray:
        """The 4 x 4 transform taking a point in ``source`` to ``target`` (leading ``/`` ignored).

        Raises
        ------
        LookupError
            The two frames are not connected by the transforms received.
        """
        target, source = target.lstrip("/"), source.lstrip("/")
        from_source = self._ancestors(source)
        for anc, t_anc_target in self._ancestors(target).items():  # nearest first
            if anc in from_source:
                return np.linalg.inv(t_anc_target) @ from_source[anc]
        known = ", ".join(self.frames()) or "none"
        raise LookupError(f"tf: no static transform chain from {source!r} to {target!r} (frames known: {known})")


__all__ = ["MAX_DEPTH", "StaticTransforms"]
