"""Numbered rotation of an output file: ``vpp.rrd`` newest, then ``vpp.1.rrd``, ``vpp.2.rrd``, ...

The Rerun sink rotates its recording by size with :func:`rotate`; a service
that resumes in a folder holding a previous run's outputs rotates
``summary.json`` and the recording the same way (``summary.1.json`` is the
run before, ...), so a restart keeps a bounded history instead of replacing it.
"""

from __future__ import annotations

import contextlib
from pathlib import Path


def rotated_paths(path: Path, max_files: int) -> list[Path]:
    """The files of a rotated output, newest first: ``vpp.rrd``, ``vpp.1.rrd``, ... ``vpp.<max_files-1>.rrd``."""
    return [path] + [path.with_name(f"{path.stem}.{i}{path.suffix}") for i in range(1, max_files)]


def rotate(path: Path, max_files: int) -> list[Path]:
    """Shift ``path`` to ``<stem>.1<suffix>``, that one to ``.2``, ...; the oldest of ``max_files`` is deleted.

    Afterwards ``path`` is free. Gaps in the numbering are kept (only existing
    files move), each move is one ``rename``.

    Parameters
    ----------
    path : Path
        The newest file (e.g. ``summary.json``).
    max_files : int
        Files kept, ``path`` included (>= 1; 1 deletes ``path``).

    Returns
    -------
    list of Path
        The rotated files that exist afterwards, newest first.

    Raises
    ------
    ValueError
        ``max_files`` < 1.
    OSError
        A rename or the deletion failed (folder not writable, ...).
    """
    if max_files < 1:
        raise ValueError(f"max_files: must be >= 1, got {max_files}")
    files = rotated_paths(Path(path), max_files)
    with contextlib.suppress(FileNotFoundError):
        files[-1].unlink()
    for older, newer in zip(reversed(files[1:]), reversed(files[:-1]), strict=True):
        if newer.exists():
            newer.replace(older)
    return [p for p in files[1:] if p.exists()]


__all__ = ["rotate", "rotated_paths"]
