"""Files source: replay frames from disk.

Two layouts:

- ``format = "dataset"``: any dataset :func:`vpp_service.datasets.open_dataset`
  reads (``dataset`` = a name or ``"auto"``, ``root`` = its folder). Frames that
  carry their own sparse depth (your recordings: the ``folder`` layout's
  ``sparse/``, :mod:`vpp_service.datasets.sparse_input`) keep it and need no
  ground truth; the others get a simulated sensor drawn from their ground truth
  per frame (``sensor``, default ``uniform`` 5 %; ``"none"`` to send frames
  without depth). :meth:`FilesSource.check_paths` (``run --check``) fails when
  the sensor would need ground truth the folder lacks.
- ``format = "msgpack"``: a folder of wire-format v1 ``in/frame`` messages
  (``*.msgpack``, replayed in name order; e.g. written by the ``record`` sink,
  :mod:`vpp_service.sinks.record`). Every file is validated like a network
  message; a bad file is rejected and skipped. Frames that carry sparse depth
  keep it (``sensor`` only fills in frames without any); ``scale`` is not
  applied. With ``format = "dataset"`` and ``dataset = "auto"``, a folder that
  matches no dataset layout but holds ``*.msgpack`` files is replayed this way.

An item that cannot be read (a corrupt image, a folder named ``*.msgpack``, a
file that vanished) is rejected, counted and skipped; the rest is replayed.

``rate_hz`` paces the replay (0 = as fast as possible), ``loop`` restarts at the
end, ``count`` caps the number of frames (0 = no cap). Frames are renumbered
``seq`` = 0, 1, ... in replay order and stamped with the wall clock.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Literal

from vpp_service.frame import StereoFrame
from vpp_service.settings import NonEmpty, Options, Range
from vpp_service.sources.base import SOURCES, Emit, Pacer, Reject, Source, SourceContext
from vpp_service.sources.sim import build_sensor_or_none, check_sensor_input, scale_frame
from vpp_service.transport import wire

if TYPE_CHECKING:
    from vpp_service.datasets.base import Dataset
    from vpp_service.sources.sensors import NominalGeometry, Sensor


@dataclass(frozen=True)
class FilesSourceOptions(Options):
    """Options of the ``files`` source.

    Attributes
    ----------
    root : str
        Dataset folder, or folder of ``*.msgpack`` frames (required).
    format : {"dataset", "msgpack"}
        Layout of ``root``.
    dataset : str
        Dataset reader name or ``"auto"`` (``format = "dataset"``).
    rate_hz : float
        Replay rate; 0 = as fast as possible.
    loop : bool
        Restart from the first frame after the last.
    count : int
        Frames to emit in total; 0 = no cap.
    scale : float
        Resize factor in (0, 1] for dataset frames.
    sensor : str
        Sensor simulator for frames without sparse depth, or ``"none"``.
    sensor_options : dict
        Options of the sensor simulator.
    seed : int
        Base sensor seed (``seed + seq`` per frame).
    """

    root: Annotated[str, NonEmpty()] = ""
    format: Literal["dataset", "msgpack"] = "dataset"
    dataset: str = "auto"
    rate_hz: Annotated[float, Range(0.0, 10000.0)] = 0.0
    loop: bool = False
    count: Annotated[int, Range(0)] = 0
    scale: Annotated[float, Range(0.0, 1.0, lo_open=True)] = 1.0
    sensor: str = "uniform"
    sensor_options: dict[str, object] = field(default_factory=lambda: {"density": 0.05})
    seed: int = 0


@SOURCES.register("files")
class FilesSource(Source):
    """Replay a dataset or a folder of wire-format frames (see the module docstring)."""

    finite = True  # a replay: back-pressured, loses nothing by default

    Options = FilesSourceOptions
    options: FilesSourceOptions

    def __init__(self, options: FilesSourceOptions, context: SourceContext) -> None:
        super().__init__(options, context)
        self._dataset: Dataset | None = None
        self._files: list[Path] = []
        self.sensor: Sensor[NominalGeometry] | None = None

    @classmethod
    def check_paths(
        cls, options: FilesSourceOptions, section: str, created_dirs: frozenset[Path] = frozenset()
    ) -> None:
        """``root`` must be an existing folder; a dataset's frames need ground truth or their own sparse depth.

        Raises
        ------
        FileNotFoundError
            ``root`` is not a folder.
        ValueError
            The sensor is simulated but the dataset has neither ground truth nor
            ``sparse/`` input; or no dataset layout matches ``root``.
        """
        if not Path(options.root).expanduser().is_dir():
            raise FileNotFoundError(f"{section}.root: no such folder: {options.root}")
        if options.format == "dataset":
            check_sensor_input(options.dataset, options.root, options.sensor, section, own_sparse=True)

    def open(self) -> None:
        """Open the dataset / list the files; raises FileNotFoundError/ValueError early."""
        o = self.options
        root = Path(o.root)
        if not root.is_dir():
            raise FileNotFoundError(f"source.root: no such folder: {root}")
        self.sensor = build_sensor_or_none(o.sensor, dict(o.sensor_options))
        if o.format == "msgpack":
            self._files = sorted(root.glob("*.msgpack"))
            if not self._files:
                raise ValueError(f"source.root: no *.msgpack frames in {root}")
        else:
            from vpp_service.datasets import open_dataset

            try:
                self._dataset = open_dataset(o.dataset, root)
            except ValueError:
                # "auto" on a folder of wire frames (e.g. a recording, which is what
                # `vpp-service publish --dataset auto --root DIR` passes): replay it
                self._files = sorted(root.glob("*.msgpack")) if o.dataset == "auto" else []
                if not self._files:
                    raise
                return
            if len(self._dataset) == 0:
                raise ValueError(f"source.root: dataset {o.dataset!r} at {root} has no frames")

    def __len__(self) -> int:
        return len(self._files) if self._dataset is None else len(self._dataset)

    def _load(self, index: int) -> StereoFrame:
        if self._dataset is not None:
            return scale_frame(self._dataset[index], self.options.scale)
        path = self._files[index]
        size = path.stat().st_size
        if size > wire.DEFAULT_LIMITS.max_message_bytes:
            raise wire.WireError(f"message: {size} bytes exceeds the limit")
        return wire.decode_frame(path.read_bytes())

    def _frame(self, index: int, seq: int) -> StereoFrame:
        """Item ``index`` as frame ``seq``: its own sparse depth, else the simulated sensor's draw."""
        frame = self._load(index)
        frame = frame.with_(rig=self.context.rig, seq=seq, stamp_ns=time.time_ns(), meta=dict(frame.meta))
        if self.sensor is not None and frame.sparse_disparity is None and frame.sensor_depth is None:
            frame = self.sensor.simulate(frame, self.options.seed + seq)
        return frame

    def _item_name(self, index: int) -> str:
        if self._dataset is None:
            return str(self._files[index])
        return f"{self.options.root}[{index}] ({self._dataset.scenes[index]})"

    def run(self, emit: Emit, reject: Reject) -> None:
        """Replay until the end (or ``count``), looping if asked, or until stopped."""
        o = self.options
        pacer = Pacer(o.rate_hz)
        seq = 0
        index = 0
        n = len(self)
        while o.count == 0 or seq < o.count:
            if index >= n:
                if not o.loop:
                    return
                index = 0
            if pacer.wait(self):
                return
            try:
                frame = self._frame(index, seq)
            except Exception as exc:  # noqa: BLE001 - one unreadable item (any error) is skipped, not fatal
                self._counters["rejected"] += 1
                reject(f"{self._item_name(index)}: {exc if isinstance(exc, wire.WireError) else repr(exc)}")
                index += 1
                if index >= n and seq == 0 and not o.loop:
                    return
                if index >= n and seq == 0:
                    return  # every file is bad: looping would spin
                continue
            index += 1
            self._counters["emitted"] += 1
            emit(frame)
            seq += 1


__all__ = ["FilesSource", "FilesSourceOptions"]
