"""What the sinks that write files into a folder share (``files``, ``record``).

:class:`FolderSink` checks (or creates) the folder at open time; file names
come from a ``str.format`` pattern (:func:`check_pattern`, :meth:`FolderSink.frame_stem`)
over validated parts only (:func:`check_name`: a frame's ``rig`` comes from the
network), and every path is checked to stay inside the folder after resolution
(:func:`path_inside`); :func:`write_atomic` writes a file to a temporary name in its destination
folder and renames it into place, so readers never see a partial file. Files get the mode an ordinary
``open()`` gives (``0o666`` less the process umask), not ``tempfile.mkstemp``'s private ``0o600``.
"""

from __future__ import annotations

import os
import re
import secrets
import tempfile
from abc import abstractmethod
from collections.abc import Callable
from pathlib import Path
from typing import Protocol

import numpy as np

from vpp_service.frame import FusionResult
from vpp_service.sinks.base import Sink, SinkContext

#: Fields a file-name pattern may use, with the sample values used to check it.
PATTERN_FIELDS = {"rig": "rig0", "seq": 0, "stamp_ns": 0, "name": "scene"}


#: What a name part (``rig``, ``name``) and a whole file-name stem may look like: no path separators,
#: no NUL or control characters, no leading dot (hidden files, ``.`` and ``..``), at most 200 characters.
_SAFE_NAME = re.compile(r"[A-Za-z0-9_\-][A-Za-z0-9_.\-]{0,199}")


def check_name(value: object, what: str) -> str:
    """``value`` when it is a safe file-name part, else ValueError.

    Safe: 1 to 200 characters from ``A-Z a-z 0-9 _ - .``, not starting with ``.``
    (so no path separators, NUL, ``..`` or hidden names).

    Raises
    ------
    ValueError
        Naming ``what``: not a string, or not a safe name.
    """
    if not isinstance(value, str) or _SAFE_NAME.fullmatch(value) is None:
        raise ValueError(f"{what}: {value!r} is not a safe file name (1-200 of A-Z a-z 0-9 _ - ., no leading dot)")
    return value


def path_inside(folder: Path, name: str) -> Path:
    """``folder / name`` after checking that it resolves to a file directly inside ``folder``.

    Raises
    ------
    ValueError
        ``name`` is not a safe name, or the resolved path (symbolic links
        followed) leaves ``folder``.
    """
    check_name(name, "file name")
    base = folder.resolve()
    path = (base / name).resolve()
    if path.parent != base:
        raise ValueError(f"file name: {name!r} resolves to {str(path)!r}, outside {str(base)!r}")
    return folder / name


#: What :func:`check_pattern` accepts, in words (option help and errors).
PATTERN_RULE = "a pattern over {rig}, {seq}, {stamp_ns}, {name} giving a plain, non-hidden file name"


def check_pattern(pattern: str) -> None:
    """Validate a file-name pattern over :data:`PATTERN_FIELDS`.

    Raises
    ------
    ValueError
        Naming ``pattern``: not a valid pattern, or not a plain, non-hidden file name.
    """
    try:
        stem = pattern.format(**PATTERN_FIELDS)
    except (KeyError, IndexError, ValueError) as exc:
        raise ValueError(
            f"pattern: {pattern!r} is not a valid pattern over {sorted(PATTERN_FIELDS)} ({exc!r})"
        ) from None
    if not stem or "/" in stem or "\\" in stem or stem in (".", "..") or stem.startswith("."):
        raise ValueError(f"pattern: {pattern!r} must give a plain, non-hidden file name, got {stem!r}")


def _create_temp(path: Path) -> tuple[int, Path]:
    """Create a new, empty temporary file beside ``path``; its descriptor (open for writing) and path.

    Created with mode ``0o666`` so the kernel applies the umask (and a default ACL) as for any new file:
    the renamed result is as readable as a file written in place. ``O_EXCL`` with a random name makes
    it ours alone, as ``tempfile.mkstemp`` does.
    """
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0)
    for _ in range(100):
        tmp = path.parent / f".{path.name}.{secrets.token_hex(6)}.tmp"
        try:
            return os.open(tmp, flags, 0o666), tmp
        except FileExistsError:
            continue
    raise FileExistsError(f"{path}: no free temporary name in {str(path.parent)!r}")  # pragma: no cover


def write_atomic(path: Path, data: bytes | Callable[[str], object], overwrite: bool) -> None:
    """Write ``path`` via a temporary file in the same folder, then rename.

    The file gets the mode a plain ``open(path, "w")`` would give it: ``0o666`` less the umask.

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
    fd, tmp = _create_temp(path)
    tmp_name = str(tmp)
    try:
        if callable(data):
            os.close(fd)
            data(tmp_name)
        else:
            with os.fdopen(fd, "wb") as fh:
                fh.write(data)
        if overwrite:
            tmp.replace(path)
        else:
            try:  # link() fails if the target exists: atomic no-clobber
                os.link(tmp, path)
            except FileExistsError:
                raise FileExistsError(f"{path} exists and overwrite = false") from None
            except OSError:  # file system without hard links: check, then rename
                if path.exists():
                    raise FileExistsError(f"{path} exists and overwrite = false") from None
                tmp.replace(path)
    finally:
        tmp.unlink(missing_ok=True)


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
        Path(probe).unlink()
    except OSError as exc:
        raise PermissionError(f"{key}: {what} {str(d)!r} is not writable: {exc}") from None


class FolderOptions(Protocol):
    """The options every folder sink has (read-only: its ``Options`` is a frozen dataclass)."""

    @property
    def dir(self) -> str:
        """Output folder (``~`` expanded)."""

    @property
    def create_dir(self) -> bool:
        """Create the folder (with parents) when it is missing."""

    @property
    def pattern(self) -> str:
        """File-name stem pattern over :data:`PATTERN_FIELDS`."""


class FolderSink(Sink):
    """Base of the sinks that write files into one folder (``options.dir``).

    Subclasses set ``Options`` (a dataclass with ``dir``, ``create_dir`` and
    ``pattern``, see :class:`FolderOptions`), ``NAME``, ``DIR_KEY`` / ``DIR_WHAT`` for error messages,
    and :meth:`write_one`, which :meth:`write` calls once it checked the sink and the result.
    """

    options: FolderOptions
    DIR_KEY = "sinks.dir"
    DIR_WHAT = "output folder"
    NAME = "folder"

    def __init__(self, options: FolderOptions, context: SinkContext | None = None) -> None:
        if not isinstance(options, self.Options):
            raise TypeError(f"options: must be {self.Options.__name__}, got {type(options).__name__}")
        super().__init__(options, context or SinkContext())
        self._dir = Path(options.dir).expanduser()
        self._open = False

    @classmethod
    def check_paths(cls, options: FolderOptions, section: str, created_dirs: frozenset[Path] = frozenset()) -> None:
        """``dir`` must be a folder, or missing with ``create_dir`` (or created by the service)."""
        d = Path(options.dir).expanduser()
        if d.exists():
            if not d.is_dir():
                raise NotADirectoryError(f"{section}.dir: {str(d)!r} is not a folder")
        elif not options.create_dir and d.resolve() not in created_dirs:
            raise FileNotFoundError(
                f"{section}.dir: {cls.DIR_WHAT} {str(d)!r} does not exist (create it or set create_dir = true)"
            )

    def open(self) -> None:
        """Check that ``dir`` exists (or create it) and is writable.

        Raises
        ------
        FileNotFoundError
            ``dir`` is missing and ``create_dir`` is false.
        NotADirectoryError
            ``dir`` exists but is not a folder.
        PermissionError
            ``dir`` cannot be created or written to.
        """
        prepare_dir(self._dir, self.options.create_dir, self.DIR_KEY, self.DIR_WHAT)
        self._open = True

    def write(self, result: FusionResult) -> None:
        """Write ``result`` (synchronously, :meth:`write_one` writes).

        Raises
        ------
        TypeError
            If ``result`` is not a FusionResult.
        RuntimeError
            If the sink is not open.
        """
        if not self._open:
            raise RuntimeError(f"{self.NAME} sink: write() before open() or after close()")
        if not isinstance(result, FusionResult):
            raise TypeError(f"result: must be a FusionResult, got {type(result).__name__}")
        self.write_one(result)

    @abstractmethod
    def write_one(self, result: FusionResult) -> None:
        """Write the files of one result."""

    def close(self, timeout: float = 5.0) -> None:
        """Nothing is buffered (writes are synchronous); marks the sink closed."""
        self._open = False

    def frame_stem(self, result: FusionResult) -> str:
        """File-name stem of ``result`` from ``options.pattern``, built from validated parts only.

        ``rig`` (it comes from the network) must be a safe name (:func:`check_name`),
        ``seq`` and ``stamp_ns`` non-negative integers, and the stem itself a safe name.

        Raises
        ------
        TypeError
            If ``result`` is not a FusionResult.
        ValueError
            A part or the stem is not a safe file name (e.g. a ``rig`` of ``"../x"``).
        """
        if not isinstance(result, FusionResult):
            raise TypeError(f"result: must be a FusionResult, got {type(result).__name__}")
        fr = result.frame
        rig = check_name(fr.rig or self.context.rig, "frame.rig")
        seq, stamp = fr.seq, fr.stamp_ns
        for what, v in (("frame.seq", seq), ("frame.stamp_ns", stamp)):
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
                raise ValueError(f"{what}: must be a non-negative integer, got {v!r}")
        return check_name(
            self.options.pattern.format(rig=rig, seq=int(seq), stamp_ns=int(stamp), name=fr.name or "frame"), "stem"
        )


__all__ = [
    "PATTERN_FIELDS",
    "FolderOptions",
    "FolderSink",
    "check_name",
    "check_pattern",
    "path_inside",
    "prepare_dir",
    "write_atomic",
]
