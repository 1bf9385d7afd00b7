"""Output folders and atomic file writes of the file-producing sinks (``files``, ``record``).

A file is written to a temporary name in its destination folder and renamed
into place, so readers never see a partial file.
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Callable


def write_atomic(path: Path, data: bytes | Callable[[str], object], overwrite: bool) -> None:
    """Write ``path`` via a temporary file in the same folder, then rename.

    Parameters
    ----------
    path : Path
        Destination file.
    data : bytes or callable
        The contents, or a function writing them to the temporary path it is given.
    overwrite : bool
        Replace an existing ``path``; when false an existing file raises and is
        left untouched (no-clobber is atomic where hard links are supported).

    Raises
    ------
    FileExistsError
        ``path`` exists and ``overwrite`` is false.
    OSError
        The folder is not writable, the disk is full, ...
    """
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        if callable(data):
            os.close(fd)
            data(tmp)
        else:
            with os.fdopen(fd, "wb") as fh:
                fh.write(data)
        if overwrite:
            os.replace(tmp, path)
        else:
            try:  # link() fails if the target exists: atomic no-clobber
                os.link(tmp, path)
            except FileExistsError:
                raise FileExistsError(f"{path} exists and overwrite = false") from None
            except OSError:  # file system without hard links: check, then rename
                if path.exists():
                    raise FileExistsError(f"{path} exists and overwrite = false") from None
                os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def prepare_dir(d: Path, create: bool, key: str, what: str = "output folder") -> None:
    """Check (and with ``create`` make) a sink's output folder before the run.

    Parameters
    ----------
    d : Path
        The folder.
    create : bool
        Create it (with parents) when missing.
    key : str
        Config key named in errors, e.g. ``"sinks.files.dir"``.
    what : str
        How errors call the folder.

    Raises
    ------
    FileNotFoundError, NotADirectoryError, PermissionError
        Missing (and not created), not a folder, or not writable.
    """
    if create and not d.exists():
        try:
            d.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise PermissionError(f"{key}: cannot create {str(d)!r}: {exc}") from None
    if not d.exists():
        raise FileNotFoundError(f"{key}: {what} {str(d)!r} does not exist (create it or set create_dir = true)")
    if not d.is_dir():
        raise NotADirectoryError(f"{key}: {str(d)!r} is not a folder")
    try:  # os.access lies for root and on read-only mounts; really try
        fd, probe = tempfile.mkstemp(prefix=".vpp-probe-", dir=d)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise PermissionError(f"{key}: {what} {str(d)!r} is not writable: {exc}") from None


__all__ = ["prepare_dir", "write_atomic"]
