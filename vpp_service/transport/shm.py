"""Publish large payloads from a Zenoh shared-memory pool (explicit SHM), falling back to a plain put.

Zenoh already moves messages between processes on one host through shared
memory (its implicit "transport optimization"), but then ``put(bytes)`` copies
the payload into the pool inside the call.  Writing the serialized message
into a buffer allocated from our own :class:`zenoh.shm.ShmProvider` and
publishing that buffer skips that copy.  Subscribers see an
ordinary payload; to a peer on another host Zenoh sends the bytes over the
network as usual.

Nothing here ever blocks or loses a message: when shared memory is unavailable
(no ``/dev/shm``, a Zenoh build without it, the pool full because subscribers
still hold earlier buffers) the message goes out with a plain ``put`` and the
fallback is counted.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # zenoh is imported where it is used
    import zenoh
    import zenoh.shm

log = logging.getLogger(__name__)

#: Payloads smaller than this are put directly (the copy is negligible).
MIN_SHM_BYTES = 64 * 1024


class ShmPutter:
    """Put payloads through a process-local shared-memory pool when possible.

    Parameters
    ----------
    pool_mb : int
        Size of the pool in MiB (allocated in ``/dev/shm`` on first use; it
        must hold the messages subscribers have not released yet: a few frames).
        0 disables shared memory: every put is plain.

    Attributes
    ----------
    shm_puts, plain_puts, fallbacks : int
        Messages sent from the pool, sent plainly by choice (small or disabled),
        and sent plainly because the pool could not serve them.
    """

    def __init__(self, pool_mb: int = 64) -> None:
        if isinstance(pool_mb, bool) or not isinstance(pool_mb, int) or not 0 <= pool_mb <= 4096:
            raise ValueError(f"pool_mb must be an int in [0, 4096], got {pool_mb!r}")
        self.pool_bytes = pool_mb << 20
        #: The pool and its allocation policy, once opened.
        self._pool: tuple[zenoh.shm.ShmProvider, zenoh.shm.GarbageCollect] | None = None
        self._tried = pool_mb == 0
        self.shm_puts = self.plain_puts = self.fallbacks = 0

    @property
    def active(self) -> bool:
        """True once the pool exists (after the first large put)."""
        return self._pool is not None

    def _open(self) -> None:
        self._tried = True
        try:
            import zenoh.shm as zshm

            self._pool = (zshm.ShmProvider.default_backend(self.pool_bytes), zshm.GarbageCollect())
        except Exception as exc:  # noqa: BLE001 - no SHM in this build / platform, /dev/shm too small: plain puts
            log.info("shared memory unavailable (%s); publishing with plain puts", exc)
            self._pool = None

    def put(self, publisher: zenoh.Publisher, payload: bytes | bytearray | Sequence[bytes | bytearray]) -> None:
        """Publish ``payload`` on ``publisher``: from the pool if it fits, else plainly.

        ``payload`` may be a list of parts whose concatenation is the message
        (:func:`vpp_service.transport.wire.encode_output_parts`): they are
        written one after the other into the pool buffer, never joined there.
        """
        parts = [payload] if isinstance(payload, (bytes, bytearray)) else list(payload)
        n = sum(len(p) for p in parts)
        if n >= MIN_SHM_BYTES and n <= self.pool_bytes:
            if not self._tried:
                self._open()
            if self._pool is not None:
                provider, policy = self._pool
                try:
                    buf = provider.alloc(n, policy)
                except Exception as exc:  # noqa: BLE001 - pool exhausted or fragmented: never lose the message
                    self.fallbacks += 1
                    if self.fallbacks == 1:
                        log.info("shared-memory pool could not serve %d bytes (%s); plain put", n, exc)
                else:
                    off = 0
                    for p in parts:
                        buf[off : off + len(p)] = p
                        off += len(p)
                    publisher.put(buf)
                    self.shm_puts += 1
                    return
        self.plain_puts += 1
        publisher.put(parts[0] if len(parts) == 1 else b"".join(parts))

    def stats(self) -> dict[str, int]:
        """Counters: ``shm_puts``, ``plain_puts``, ``fallbacks``."""
        return {"shm_puts": self.shm_puts, "plain_puts": self.plain_puts, "fallbacks": self.fallbacks}


__all__ = ["MIN_SHM_BYTES", "ShmPutter"]
