"""The ``record`` sink: save every INPUT frame as a wire-format v1 message for replay.

Like a dora-rs recording, the service can record what it received and a later
run (or ``vpp-service publish``) can play it back. For each
:class:`~vpp_service.frame.FusionResult` the sink writes ``result.frame`` --
the stereo pair, calibration, sparse depth and ground truth when present -- as
one ``in/frame`` message (:func:`vpp_service.transport.wire.encode_frame`) to
``<dir>/<pattern>.msgpack``. That is exactly the layout the ``files`` source
replays (``format = "msgpack"``, files in name order), so a recording is played
back unchanged by::

    [source]
    type = "files"
    format = "msgpack"
    root = "<dir>"

The default pattern ``{rig}_{seq:09d}`` sorts by sequence number. Sparse depth
is recorded as the fusion consumes it: ``sparse_disparity`` as disparity points
when the frame has it (simulated sensors also attach the metric depth it was
derived from, and metric points received over the wire arrive with their
disparity too; that metric copy is not recorded), else ``sensor_depth`` as
metric points.
Fields the wire format does not carry (``name``, ``nocc_mask``, ``meta``) are
not recorded.

Images are stored as lossless PNG by default (``enc = "png"``: the Motorcycle
pair, 500 x 741 RGB, takes about 0.6x the bytes of raw but is far slower to
encode; choose ``raw`` for high frame rates). Ground
truth and sparse depth are float32 and always stored raw. Lossy JPEG is not
offered: a recording must replay bit-exactly. Writes are synchronous, in the
pipeline's sink thread, like the ``files`` sink.

Limits: ``max_frames`` stops after that many recorded frames and
``max_bytes`` is a hard disk budget (a frame that would take the recording past
it is not written, and recording stops there so the recording stays
contiguous). Either limit is logged once; frames arriving after it are counted
in ``stats()["skipped"]``.

Every file is written to a temporary name in the same folder and renamed into
place, so a reader (or a replay running concurrently) never sees a partial
file. After :meth:`RecordSink.open` succeeded, write failures (disk full, an
existing file with ``overwrite = false``, a frame without calibration) are
logged and counted in ``stats()["errors"]``, never raised.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal

from vpp_service.frame import FusionResult
from vpp_service.settings import NonEmpty, Options, Range, Satisfies
from vpp_service.sinks.base import SINKS, SinkContext
from vpp_service.sinks.folder import PATTERN_RULE, FolderSink, check_pattern, path_inside, write_atomic
from vpp_service.transport import wire

log = logging.getLogger(__name__)

#: Image encodings a recording may use (both lossless).
ENCODINGS = ("raw", "png")
#: File name extension of recorded frames (what the ``files`` source globs for).
EXTENSION = ".msgpack"


@dataclass(frozen=True)
class RecordSinkOptions(Options):
    """Options of the ``record`` sink.

    Attributes
    ----------
    dir : str
        Recording folder (required); must exist and be writable unless
        ``create_dir`` is true.
    create_dir : bool
        Create ``dir`` (with parents) at open instead of failing when missing.
    enc : {"raw", "png"}
        Image encoding inside the messages (default ``"png"``: lossless, smaller).
    max_frames : int
        Stop recording after this many frames; 0 = no limit.
    max_bytes : int
        Disk budget in bytes for this recording; 0 = no limit.
    overwrite : bool
        Replace existing files (default false: an existing file is an error,
        counted, and the frame is not written).
    pattern : str
        File name stem (``.msgpack`` is appended), a ``str.format`` pattern over
        ``rig``, ``seq``, ``stamp_ns``, ``name``; must not contain path
        separators. Replay order is name order, so keep it sortable in time,
        e.g. ``"{rig}_{stamp_ns}"`` to record several runs into one folder.
    """

    dir: Annotated[str, NonEmpty()]
    create_dir: bool = False
    enc: Literal["raw", "png"] = "png"
    max_frames: Annotated[int, Range(0)] = 0
    max_bytes: Annotated[int, Range(0)] = 0
    overwrite: bool = False
    pattern: Annotated[str, Satisfies(check_pattern, PATTERN_RULE)] = "{rig}_{seq:09d}"


@SINKS.register("record")
class RecordSink(FolderSink):
    """Record every input frame as a wire-format ``.msgpack`` file (see the module docstring).

    Parameters
    ----------
    options : RecordSinkOptions
        Parsed options (see :func:`vpp_service.sinks.base.build_sink`).
    context : SinkContext
        Service context; ``context.rig`` is used when a frame has no rig name.

    Examples
    --------
    >>> sink = build_sink("record", {"dir": "/tmp/rec", "create_dir": True, "max_frames": 100})  # doctest: +SKIP
    >>> with sink:
    ...     sink.write(result)
    >>> src = build_source("files", {"root": "/tmp/rec", "format": "msgpack"})  # doctest: +SKIP

    Counters (``stats()``): ``written`` frames recorded, ``errors`` frames that
    failed, ``skipped`` frames not recorded because a limit was reached,
    ``bytes`` bytes recorded, ``dropped`` (always 0: writes are synchronous).
    """

    Options = RecordSinkOptions
    options: RecordSinkOptions

    @classmethod
    def needs_depth(cls, options: RecordSinkOptions) -> bool:
        """False: a recording holds the input frame, not the fused depth."""
        return False

    DIR_KEY = "sinks.record.dir"
    DIR_WHAT = "recording folder"
    NAME = "record"

    def __init__(self, options: RecordSinkOptions, context: SinkContext | None = None) -> None:
        super().__init__(options, context)
        self._stopped: str | None = None
        self._counters["skipped"] = 0
        self._counters["bytes"] = 0

    @property
    def stopped(self) -> str | None:
        """Why recording stopped (``"max_frames"`` / ``"max_bytes"``), or None while recording."""
        return self._stopped

    # -- writing --------------------------------------------------------------------
    def output_path(self, result: FusionResult) -> Path:
        """The file :meth:`write` records ``result.frame`` to.

        Raises
        ------
        TypeError
            If ``result`` is not a FusionResult.
        ValueError
            The file name would not be safe or would leave ``dir`` (see :meth:`frame_stem`).
        """
        return path_inside(self._dir, f"{self.frame_stem(result)}{EXTENSION}")

    def _stop(self, reason: str, detail: str) -> None:
        self._stopped = reason
        log.warning("record sink: %s reached (%s); recording to %s stopped", reason, detail, self._dir)

    def write_one(self, result: FusionResult) -> None:
        """Record ``result.frame`` (synchronously, atomically; errors counted and logged)."""
        if self._stopped is not None:
            self._counters["skipped"] += 1
            return
        try:
            path = self.output_path(result)
        except ValueError as exc:  # an unsafe name: nothing is written, counted
            self._counters["errors"] += 1
            log.warning("record sink: not recording frame seq=%s: %s", result.frame.seq, exc)
            return
        o = self.options
        try:
            frame = result.frame
            if not frame.rig:
                frame = frame.with_(rig=self.context.rig)
            # a frame may carry both sparse disparity and the metric depth it came from
            # (the simulators do); record the one the fusion uses, so a replay is exact
            kind = "disparity_points" if frame.sparse_disparity is not None else "auto"
            data = wire.encode_frame(frame, o.enc, kind)
        except Exception as exc:  # noqa: BLE001 - counted, logged, never raised
            self._counters["errors"] += 1
            log.warning("record sink: cannot encode frame for %s: %s", path, exc)
            return
        if o.max_bytes and self._counters["bytes"] + len(data) > o.max_bytes:
            self._counters["skipped"] += 1
            self._stop(
                "max_bytes",
                f"{self._counters['bytes']} bytes recorded, next frame needs {len(data)}, budget {o.max_bytes}",
            )
            return
        try:
            write_atomic(path, data, o.overwrite)
        except Exception as exc:  # noqa: BLE001 - counted, logged, never raised
            self._counters["errors"] += 1
            log.warning("record sink: cannot write %s: %s", path, exc)
            return
        self._counters["written"] += 1
        self._counters["bytes"] += len(data)
        if o.max_frames and self._counters["written"] >= o.max_frames:
            self._stop("max_frames", f"{self._counters['written']} frames")


__all__ = ["ENCODINGS", "EXTENSION", "RecordSink", "RecordSinkOptions"]
