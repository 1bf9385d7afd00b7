"""A service that starts again in its output folder: resume there, keeping the previous run's outputs.

``vpp-service run`` refuses to start over a previous run's outputs
(:func:`~vpp_service.service.config.previous_outputs`) unless told what to do
with them: ``service.overwrite`` replaces them, ``service.resume`` keeps them.
A long-running service (a network source, or a config run by the systemd unit,
whose ``ExecStart`` passes ``--resume``) must come back after a crash or a
reboot, so it resumes; a one-shot run (``vpp-service run`` on the embedded
default) still refuses.

Resuming (:func:`resume_outputs`), before anything opens:

* ``<out>/summary.json`` becomes ``summary.1.json`` (the run before that
  ``summary.2.json``, ...); at most :data:`KEEP_SUMMARIES` are kept, the new
  run's own included, the oldest deleted.
* A Rerun ``save`` recording (``vpp.rrd``) is rotated as its size cap rotates
  it: ``vpp.1.rrd``, ... up to the sink's ``max_files``.
* The files and record sinks go on writing into their folders. A file name
  that is already there is not replaced (unless the sink's own ``overwrite``):
  it is counted as an error, so a source that starts its ``seq`` again (the
  simulator) wants a ``pattern`` with ``{stamp_ns}``.
"""

from __future__ import annotations

import logging
from pathlib import Path

from vpp_service.service.config import ServiceConfig
from vpp_service.sinks.rotation import rotate
from vpp_service.sources import SOURCES

log = logging.getLogger(__name__)

#: ``summary.json`` files kept in a resumed ``out``: the current one and ``summary.1.json`` ... ``summary.9.json``.
KEEP_SUMMARIES = 10


def resumes(cfg: ServiceConfig) -> bool:
    """Whether a start over a previous run's outputs keeps them (resumes) rather than refusing.

    ``service.overwrite`` wins (it replaces them); ``service.resume = "auto"``
    resumes for a network source (``Source.network``: ``zenoh``, ``ros2``).
    """
    s = cfg.service
    if s.overwrite:
        return False
    if s.resume == "auto":
        return bool(SOURCES.get(cfg.source.name).network)
    return bool(s.resume)


def resume_outputs(cfg: ServiceConfig) -> list[str]:
    """Rotate the previous run's single-file outputs out of the new run's way (see the module docstring).

    Returns
    -------
    list of str
        One ``"old -> new"`` per moved file, for the log.

    Raises
    ------
    OSError
        A rename failed (the folder is not writable, ...).
    """
    moved: list[str] = []
    targets: list[tuple[Path, int]] = [(Path(cfg.service.out).expanduser() / "summary.json", KEEP_SUMMARIES)]
    for spec in cfg.sinks:
        o = spec.options
        path, keep = getattr(o, "path", None), getattr(o, "max_files", None)
        if getattr(o, "mode", "save") == "save" and isinstance(path, str) and isinstance(keep, int):
            targets.append((Path(path).expanduser(), keep))  # a recording rotated by size: the same numbering
    for path, keep in targets:
        if path.is_file():
            kept = rotate(path, keep)
            moved.append(f"{path} -> {kept[0]}" if kept else f"{path} deleted (max_files = {keep})")
    for line in moved:
        log.info("resuming: %s", line)
    return moved


__all__ = ["KEEP_SUMMARIES", "resume_outputs", "resumes"]
