"""A small text progress bar for long evaluations (no third-party dependency)."""

from __future__ import annotations

import sys
import time
from typing import TextIO


class ProgressBar:
    r"""Callable ``progress(done, total, label)`` printing ``[ 3/26] Art census-sgm vpp 0.05 ...``.

    On a terminal the line is rewritten in place (``\r``); otherwise one line
    per step is written. Elapsed time and a simple ETA are appended.

    Parameters
    ----------
    stream : text stream, optional
        Where to write (default ``sys.stderr``).
    """

    def __init__(self, stream: TextIO | None = None) -> None:
        self.stream = stream if stream is not None else sys.stderr
        self.t0 = time.perf_counter()
        self._tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self._width = 0

    def __call__(self, done: int, total: int, label: str) -> None:
        """Report that ``done`` of ``total`` steps are finished and ``label`` runs next (``done >= total``: the end).

        Parameters
        ----------
        done : int
            Steps finished.
        total : int
            Number of steps.
        label : str
            What runs next (not shown at the end).
        """
        elapsed = time.perf_counter() - self.t0
        n = len(str(total))
        if done >= total:
            line = f"[{done:>{n}}/{total}] done in {elapsed:.1f} s"
        else:
            eta = f", eta {elapsed / done * (total - done):.0f} s" if done else ""
            line = f"[{done + 1:>{n}}/{total}] {label} \u2026 ({elapsed:.1f} s{eta})"
        if self._tty:
            pad = max(0, self._width - len(line))
            self.stream.write("\r" + line + " " * pad + ("\n" if done >= total else ""))
            self._width = len(line)
        else:
            self.stream.write(line + "\n")
        self.stream.flush()


__all__ = ["ProgressBar"]
