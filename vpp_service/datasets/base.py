"""The dataset interface, the ``DATASETS`` registry and :func:`open_dataset`.

A dataset is a folder of rectified stereo scenes. Readers subclass
:class:`Dataset`, register under a name, describe their layout (used in the
"nothing matched" error of auto-detection) and implement :meth:`Dataset.detect`
and :meth:`Dataset._load`. Frames are read lazily, one per ``__getitem__``.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterator
from pathlib import Path

from vpp_service.frame import StereoFrame
from vpp_service.registry import Registry

log = logging.getLogger(__name__)

#: Reader classes by name (``middlebury2014``, ``kitti2012``, ``folder``, ...).
DATASETS: Registry[Dataset] = Registry("dataset")

#: Order in which ``open_dataset("auto", ...)`` tries the readers: more specific layouts first (ETH3D is
#: Middlebury 2014 without ``vmin``), the generic ``folder`` last. Readers registered elsewhere follow.
AUTO_ORDER: tuple[str, ...] = (
    "eth3d",
    "middlebury2014",
    "middlebury2006",
    "middlebury2003",
    "middlebury2001",
    "kitti2015",
    "kitti2012",
    "folder",
)


def scene_dirs(root: Path, predicate: Callable[[Path], bool]) -> list[Path]:
    """Scene folders of ``root``: ``[root]`` if it is a scene itself, else its matching sub-folders (sorted)."""
    if predicate(root):
        return [root]
    return sorted((p for p in root.iterdir() if p.is_dir() and predicate(p)), key=lambda p: p.name)


class Dataset:
    """A lazily loaded sequence of :class:`~vpp_service.frame.StereoFrame`.

    Parameters
    ----------
    root : str or Path
        The dataset folder (or one scene folder).

    Attributes
    ----------
    name : str
        Registry name of the reader.
    layout : str
        Human description of the files the reader expects.
    root : Path
        The folder given.
    scenes : list of str
        Scene names, in loading order.
    max_disparity : float or None
        An upper bound of the disparities in the set when known.
    has_ground_truth : bool
        Every frame carries ground-truth disparity (what a simulated sensor is
        drawn from). True for the benchmark readers; the ``folder`` reader says
        whether its ``disp/`` is there.
    has_sparse_input : bool
        Every frame carries its own sparse depth (``sparse_disparity``), e.g. the
        ``folder`` reader's ``sparse/``; a replay then needs no simulated sensor.
    """

    name: str = ""
    layout: str = ""
    has_ground_truth: bool = True
    has_sparse_input: bool = False

    def __init__(self, root: str | Path) -> None:
        if not isinstance(root, (str, Path)):
            raise TypeError(f"root: must be a path, got {type(root).__name__}")
        self.root = Path(root)
        if not self.root.is_dir():
            raise FileNotFoundError(f"root: dataset folder not found: {self.root}")
        self.scenes: list[str] = []
        self.max_disparity: float | None = None

    @classmethod
    def detect(cls, root: Path) -> bool:
        """True if ``root`` looks like this reader's layout."""
        raise NotImplementedError

    def _load(self, index: int) -> StereoFrame:
        raise NotImplementedError

    def __len__(self) -> int:
        return len(self.scenes)

    def __getitem__(self, index: int | str) -> StereoFrame:
        """Load frame ``index`` (int, negative allowed) or the scene named ``index``."""
        if isinstance(index, str):
            if index not in self.scenes:
                raise KeyError(f"index: no scene {index!r}; scenes: {', '.join(self.scenes)}")
            index = self.scenes.index(index)
        if isinstance(index, bool) or not isinstance(index, int):
            raise TypeError(f"index: must be an int or a scene name, got {type(index).__name__}")
        n = len(self.scenes)
        if not -n <= index < n:
            raise IndexError(f"index: {index} out of range for {n} scenes")
        return self._load(index % n)

    def __iter__(self) -> Iterator[StereoFrame]:
        for i in range(len(self.scenes)):
            yield self._load(i)

    def select(self, names: list[str] | None = None, limit: int | None = None) -> Dataset:
        """Restrict to the scenes in ``names`` (in that order) and/or the first ``limit``; returns self."""
        if names is not None:
            unknown = [s for s in names if s not in self.scenes]
            if unknown:
                raise ValueError(f"scenes: unknown {unknown}; known: {', '.join(self.scenes)}")
            keep = [self.scenes.index(s) for s in names]
            self._subset(keep)
        if limit is not None:
            if limit < 1:
                raise ValueError(f"limit: must be >= 1, got {limit}")
            self._subset(list(range(min(limit, len(self.scenes)))))
        return self

    def _subset(self, keep: list[int]) -> None:
        """Keep the scenes at ``keep`` (subclasses with per-scene lists extend this)."""
        for attr in ("scenes", "_dirs"):
            if hasattr(self, attr):
                seq = getattr(self, attr)
                setattr(self, attr, [seq[i] for i in keep])

    def __repr__(self) -> str:
        return f"{type(self).__name__}(root={str(self.root)!r}, scenes={len(self.scenes)})"


def reader_class(name: str) -> type[Dataset]:
    """The reader class registered as ``name``.

    Raises
    ------
    ValueError
        If no reader has that name (the message lists the known ones).
    TypeError
        If what is registered under ``name`` is not a :class:`Dataset` subclass.
    """
    cls = DATASETS.get(name)
    if not (isinstance(cls, type) and issubclass(cls, Dataset)):
        raise TypeError(f"dataset {name!r} is registered as {cls!r}, not a Dataset subclass")
    return cls


def open_dataset(name: str, root: str | Path, **opts: object) -> Dataset:
    """Open a dataset folder with a named reader, or detect the layout.

    Parameters
    ----------
    name : str
        A registered reader (see ``DATASETS.names()``) or ``"auto"``.
    root : str or Path
        The dataset folder (e.g. ``../shared/data/middlebury2005_2006_thirdsize``)
        or a single scene folder.
    **opts
        Reader options (e.g. ``scale=3`` for ``middlebury2006``).

    Raises
    ------
    FileNotFoundError
        If ``root`` is not a folder.
    ValueError
        Unknown reader, or (``auto``) no layout matched: the message lists the
        layouts looked for. Also when the matched folder has no usable scene.
    """
    if not isinstance(name, str):
        raise TypeError(f"name: must be a string, got {type(name).__name__}")
    if not isinstance(root, (str, Path)):
        raise TypeError(f"root: must be a path, got {type(root).__name__}")
    root = Path(root)
    if not root.is_dir():
        raise FileNotFoundError(f"root: dataset folder not found: {root}")
    if name == "auto":
        order = [*AUTO_ORDER, *(n for n in DATASETS.names() if n not in AUTO_ORDER)]
        for candidate in order:
            cls = reader_class(candidate)
            if cls.detect(root):
                log.info("dataset at %s detected as %s", root, candidate)
                return cls(root, **opts)
        looked = "\n".join(f"  - {n}: {reader_class(n).layout}" for n in order)
        raise ValueError(f"root: no known dataset layout found in {root}; looked for:\n{looked}")
    return reader_class(name)(root, **opts)


__all__ = ["AUTO_ORDER", "DATASETS", "Dataset", "open_dataset", "reader_class", "scene_dirs"]
