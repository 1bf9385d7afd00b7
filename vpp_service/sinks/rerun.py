"""The ``rerun`` sink: stream results to a Rerun viewer, server or ``.rrd`` file.

Modes
-----
``save``
    Write a ``.rrd`` recording to ``path`` (open it later with ``rerun vpp.rrd``).
``spawn``
    Start a local native viewer listening on ``grpc_port`` and stream to it
    (``memory_limit`` bounds the viewer's memory; oldest data is dropped).
``connect``
    Stream to a running viewer/server at ``url`` (default
    ``rerun+http://127.0.0.1:9876/proxy``).
``serve``
    Host a gRPC server on ``grpc_port`` that buffers up to ``memory_limit`` for
    late viewers (``rerun rerun+http://HOST:PORT/proxy``); with ``web_port > 0``
    a web viewer is also served on that port.

Threading and back-pressure
---------------------------
:meth:`RerunSink.write` never blocks: it applies the ``max_hz`` throttle and
hands the result to a :class:`~vpp_service.queueing.QueueWorker` (``queue_size``,
drop-oldest) whose thread converts and logs. Throttled and overflowed frames are counted in ``stats()``
(``throttled``, ``queue_dropped``; ``dropped`` is their sum). The sink uses its
own :class:`rerun.RecordingStream` (never the global one) and sets the time
per frame on the ``seq`` (sequence) and ``stamp`` (timestamp) timelines.

Entities (root = ``context.rig``)
---------------------------------
``<rig>/left``, ``<rig>/right``
    The painted pair (raw pair when VPP was disabled or ``log_painted`` false).
``<rig>/left/sparse``
    Sparse input points as 2-D points over the left image, coloured by disparity.
``<rig>/disparity``
    Dense disparity, colourised (turbo, black = invalid), same colour scale.
``<rig>/camera`` and ``<rig>/camera/depth``
    ``rr.Pinhole`` from the calibration and ``rr.DepthImage(meter=1)``: the
    viewer back-projects the depth into a 3-D point cloud, decimated so that at
    most ``max_points`` pixels are logged (``point_cloud``).
``<rig>/timing/<stage>``
    Per-stage milliseconds as scalars.

Telemetry
---------
The logging SDK collects no usage data; only the Rerun *viewer* does. In
``spawn`` mode with ``analytics = false`` (default) the sink runs the viewer's
own opt-out, ``rerun analytics disable`` (stored in the user's Rerun config),
before launching it. Viewers started by hand: run that command once.

Closing
-------
:meth:`RerunSink.close` drains the queue, flushes with a timeout and
disconnects, all bounded by ``timeout``: if the viewer is gone (``connect`` to a
dead URL) the logging thread is abandoned (daemon) rather than hanging.
"""

from __future__ import annotations

import logging
import math
import re
import shutil
import subprocess
import sys
import threading
import time
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import numpy as np

from vpp_service.frame import FusionResult
from vpp_service.queueing import QueueWorker
from vpp_service.sinks.base import SINKS, Sink, SinkContext
from vpp_service.sinks.colorize import colorize_disparity, disparity_range

if TYPE_CHECKING:
    import rerun as rr
    import rerun.blueprint as rrb

log = logging.getLogger(__name__)

_MEMORY_RE = re.compile(r"^\s*(\d+(\.\d+)?)\s*(B|KB|MB|GB|TB|KiB|MiB|GiB|TiB)\s*$|^\s*(\d+(\.\d+)?)\s*%\s*$")
_URL_RE = re.compile(r"^rerun(\+https?)?://[^/\s]+/proxy$")
_ENTITY_RE = re.compile(r"^[A-Za-z0-9_\-.]+$")


@dataclass(frozen=True)
class RerunSinkOptions:
    """Options of the ``rerun`` sink.

    Attributes
    ----------
    mode : {"save", "spawn", "connect", "serve"}
        Where the data goes (see the module docstring). Default ``"save"``.
    path : str
        ``.rrd`` file for ``save`` (default ``"vpp.rrd"``; parent must exist).
    url : str or None
        gRPC URL for ``connect`` (``rerun+http://HOST:PORT/proxy``); None =
        Rerun's default ``rerun+http://127.0.0.1:9876/proxy``.
    grpc_port : int
        Port of the spawned viewer (``spawn``) or of the served gRPC server
        (``serve``). Default 9876.
    web_port : int
        ``serve`` only: also host the web viewer on this port; 0 = no web viewer.
    max_hz : float
        At most this many frames per second are logged (wall clock); 0 = all.
    memory_limit : str
        Memory bound of the spawned viewer / the gRPC server buffer, e.g.
        ``"512MB"``, ``"2GiB"``, ``"25%"``.
    queue_size : int
        Frames waiting for the logging thread (>= 1); when full the oldest is
        dropped and counted.
    log_painted : bool
        Log the painted pair (when present) instead of the raw pair.
    point_cloud : bool
        Log pinhole + depth image for the 3-D view.
    max_points : int
        Upper bound of logged depth pixels (the depth image is decimated by an
        integer stride) and of sparse 2-D points.
    application_id : str
        Rerun application id (groups recordings in the viewer).
    recording_id : str or None
        Rerun recording id; None = ``<rig>-<random uuid>``.
    analytics : bool
        Leave the spawned viewer's usage analytics as configured (true) or
        opt out before spawning (false, default).
    """

    mode: Literal["save", "spawn", "connect", "serve"] = "save"
    path: str = "vpp.rrd"
    url: str | None = None
    grpc_port: int = 9876
    web_port: int = 0
    max_hz: float = 10.0
    memory_limit: str = "512MB"
    queue_size: int = 2
    log_painted: bool = True
    point_cloud: bool = True
    max_points: int = 200_000
    application_id: str = "vpp-service"
    recording_id: str | None = None
    analytics: bool = False

    def __post_init__(self) -> None:
        if not self.path.strip():
            raise ValueError("path: must not be empty")
        if self.url is not None and not _URL_RE.match(self.url):
            raise ValueError(f"url: must look like rerun+http://HOST:PORT/proxy, got {self.url!r}")
        if not 1 <= self.grpc_port <= 65535:
            raise ValueError(f"grpc_port: must be in 1..65535, got {self.grpc_port}")
        if not 0 <= self.web_port <= 65535:
            raise ValueError(f"web_port: must be in 0..65535 (0 = off), got {self.web_port}")
        if self.web_port and self.web_port == self.grpc_port:
            raise ValueError(f"web_port: must differ from grpc_port ({self.grpc_port})")
        if not math.isfinite(self.max_hz) or self.max_hz < 0:
            raise ValueError(f"max_hz: must be a finite number >= 0 (0 = every frame), got {self.max_hz}")
        if not _MEMORY_RE.match(self.memory_limit):
            raise ValueError(f"memory_limit: must look like '512MB', '2GiB' or '25%', got {self.memory_limit!r}")
        if self.queue_size < 1:
            raise ValueError(f"queue_size: must be >= 1, got {self.queue_size}")
        if self.max_points < 1:
            raise ValueError(f"max_points: must be >= 1, got {self.max_points}")
        if not self.application_id.strip():
            raise ValueError("application_id: must not be empty")
        if self.recording_id is not None and not self.recording_id.strip():
            raise ValueError("recording_id: must not be empty when given")


def depth_stride(height: int, width: int, max_points: int) -> int:
    """Smallest integer stride ``s`` with ``ceil(H/s) * ceil(W/s) <= max_points``.

    Parameters
    ----------
    height, width : int
        Image size (> 0).
    max_points : int
        Pixel budget (>= 1).

    Returns
    -------
    int
        Stride >= 1.

    Raises
    ------
    ValueError
        On non-positive arguments.
    """
    for name, v in (("height", height), ("width", width), ("max_points", max_points)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            raise ValueError(f"{name}: must be an integer >= 1, got {v!r}")
    s = max(1, math.floor(math.sqrt(height * width / max_points)))
    while math.ceil(height / s) * math.ceil(width / s) > max_points:
        s += 1
    return s


def _disable_viewer_analytics() -> None:
    """Run ``rerun analytics disable`` (the viewer's own opt-out); log failures."""
    exe = shutil.which("rerun")
    cmd = [exe] if exe else [sys.executable, "-m", "rerun_cli"]
    try:
        subprocess.run(
            [*cmd, "analytics", "disable"],
            check=True,
            timeout=10,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
    except (OSError, subprocess.SubprocessError) as exc:
        log.warning("rerun sink: could not disable viewer analytics: %s", exc)


@SINKS.register("rerun")
class RerunSink(Sink):
    """Log results to Rerun from a dedicated thread (see the module docstring).

    Parameters
    ----------
    options : RerunSinkOptions
        Parsed options.
    context : SinkContext
        ``context.rig`` is the entity-path root.
    """

    Options = RerunSinkOptions
    options: RerunSinkOptions

    def __init__(self, options: RerunSinkOptions, context: SinkContext | None = None) -> None:
        if not isinstance(options, RerunSinkOptions):
            raise TypeError(f"options: must be RerunSinkOptions, got {type(options).__name__}")
        context = context or SinkContext()
        if not _ENTITY_RE.match(context.rig):
            raise ValueError(f"context.rig: must be letters, digits, '_', '-', '.', got {context.rig!r}")
        super().__init__(options, context)
        self._counters.update({"throttled": 0, "queue_dropped": 0})
        self._worker: QueueWorker[FusionResult] = QueueWorker(
            self._log_one,
            size=options.queue_size,
            policy="latest",
            name=f"rerun-sink-{context.rig}",
            on_start=self._attach_once,
            on_exit=self._flush,
            on_error=self._failed,
        )
        self._rec: rr.RecordingStream | None = None
        self._last_accept = -math.inf
        self._ready = threading.Event()
        self._close_deadline = math.inf
        self.server_uri: str | None = None

    # -- life cycle -----------------------------------------------------------------
    def blueprint(self) -> rrb.Blueprint:
        """The default :class:`rerun.blueprint.Blueprint` of the sink's views."""
        import rerun.blueprint as rrb

        r = f"/{self.context.rig}"
        views = [
            rrb.Horizontal(
                rrb.Spatial2DView(origin=f"{r}/left", name="left (painted) + sparse points"),
                rrb.Spatial2DView(origin=f"{r}/right", name="right (painted)"),
            ),
            rrb.Horizontal(
                rrb.Spatial2DView(origin=f"{r}/disparity", name="disparity"),
                rrb.Spatial3DView(origin=r, contents=[f"{r}/camera/**"], name="3-D"),
                rrb.TimeSeriesView(origin=f"{r}/timing", name="timing [ms]"),
                column_shares=[2, 2, 1],
            ),
        ]
        return rrb.Blueprint(rrb.Vertical(*views), collapse_panels=True)

    @classmethod
    def check_paths(cls, options: RerunSinkOptions, section: str, created_dirs: frozenset[Path] = frozenset()) -> None:
        """In ``save`` mode the ``.rrd``'s folder must exist (or be created by the service)."""
        if options.mode != "save":
            return
        path = Path(options.path).expanduser()
        if not path.parent.is_dir() and path.parent.resolve() not in created_dirs:
            raise FileNotFoundError(f"{section}.path: folder {str(path.parent)!r} does not exist")
        if path.is_dir():
            raise IsADirectoryError(f"{section}.path: {str(path)!r} is a folder, expected a .rrd file")

    def open(self) -> None:
        """Create the recording stream, attach the output and start the logging thread.

        ``save`` opens the file here (errors raise); ``spawn``/``connect``/
        ``serve`` attach on the logging thread, so an unreachable viewer never
        blocks the caller.

        Raises
        ------
        FileNotFoundError
            ``save`` into a folder that does not exist.
        RuntimeError
            If the sink is already open.
        """
        import rerun as rr

        if self._worker.started:
            raise RuntimeError("rerun sink: already open")
        o = self.options
        rec_id = o.recording_id or f"{self.context.rig}-{uuid.uuid4()}"
        self._rec = rec = rr.RecordingStream(o.application_id, recording_id=rec_id, send_properties=False)
        if o.mode == "save":
            path = Path(o.path).expanduser()
            if not path.parent.is_dir():
                raise FileNotFoundError(f"sinks.rerun.path: folder {str(path.parent)!r} does not exist")
            if path.is_dir():
                raise IsADirectoryError(f"sinks.rerun.path: {str(path)!r} is a folder, expected a .rrd file")
            rec.save(str(path), default_blueprint=self.blueprint())
            self._ready.set()
        self._worker.start()

    def _attach(self) -> None:
        """Attach the network output (runs on the logging thread)."""
        import rerun as rr

        o, rec, bp = self.options, self._recording(), self.blueprint()
        if o.mode == "spawn":
            if not o.analytics:
                _disable_viewer_analytics()
            rec.spawn(port=o.grpc_port, memory_limit=o.memory_limit, default_blueprint=bp)
        elif o.mode == "connect":
            rec.connect_grpc(o.url, default_blueprint=bp)
        elif o.mode == "serve":
            self.server_uri = rec.serve_grpc(
                grpc_port=o.grpc_port, default_blueprint=bp, server_memory_limit=o.memory_limit
            )
            if o.web_port:
                rr.serve_web_viewer(web_port=o.web_port, open_browser=False, connect_to=self.server_uri)

    def wait_ready(self, timeout: float = 5.0) -> bool:
        """Wait until the output is attached (the server runs, the viewer is spawned).

        Returns
        -------
        bool
            True when attached (or attaching failed and was counted in
            ``stats()["errors"]``), False on timeout or when not open.
        """
        return self._worker.started and self._ready.wait(timeout)

    def write(self, result: FusionResult) -> None:
        """Enqueue ``result`` for logging (non-blocking; throttled; drop-oldest).

        Raises
        ------
        TypeError
            If ``result`` is not a FusionResult.
        RuntimeError
            If the sink is not open.
        """
        if not isinstance(result, FusionResult):
            raise TypeError(f"result: must be a FusionResult, got {type(result).__name__}")
        if not self._worker.started or self._worker.closed:
            raise RuntimeError("rerun sink: write() before open() or after close()")
        now = time.monotonic()
        if self.options.max_hz > 0 and now - self._last_accept < 1.0 / self.options.max_hz:
            self._counters["throttled"] += 1
            return
        self._last_accept = now
        self._worker.put(result)

    def close(self, timeout: float = 5.0) -> None:
        """Drain, flush and disconnect within ``timeout`` seconds (never hangs).

        Frames still queued when time runs out are dropped (counted); a logging
        thread stuck on a dead viewer is abandoned (it is a daemon thread).
        """
        if not self._worker.started or self._worker.closed:
            return
        self._close_deadline = time.monotonic() + max(0.0, float(timeout))
        if not self._worker.close(timeout):
            log.warning("rerun sink: close() timed out after %.1f s; abandoning the logging thread", timeout)
            self._counters["errors"] += 1

    def stats(self) -> dict[str, int]:
        """Counters: ``written``, ``errors``, ``throttled``, ``queue_dropped`` and ``dropped`` (their sum)."""
        out = dict(self._counters)
        out["queue_dropped"] = self._worker.dropped + self._worker.discarded
        out["dropped"] = out["throttled"] + out["queue_dropped"]
        return out

    # -- logging thread -------------------------------------------------------------
    def _recording(self) -> rr.RecordingStream:
        """The sink's recording stream; only the logging thread and :meth:`open` use it.

        Raises
        ------
        RuntimeError
            Before :meth:`open` created it.
        """
        if self._rec is None:
            raise RuntimeError("rerun sink: not open")
        return self._rec

    def _attach_once(self) -> None:
        if self._ready.is_set():
            return
        try:
            self._attach()
        except Exception as exc:  # noqa: BLE001 - reported via stats and log
            log.error("rerun sink: cannot attach %s output: %s", self.options.mode, exc)
            self._counters["errors"] += 1
        self._ready.set()

    def _log_one(self, result: FusionResult) -> None:
        self._log(result)
        self._counters["written"] += 1

    def _failed(self, result: FusionResult, exc: Exception) -> None:
        # a bad frame must not kill the sink
        log.warning("rerun sink: cannot log frame %s: %s", result.frame.seq, exc)
        self._counters["errors"] += 1

    def _flush(self) -> None:
        rec = self._recording()
        try:
            rec.flush(timeout_sec=min(5.0, max(0.05, self._close_deadline - time.monotonic())))
        except Exception as exc:  # noqa: BLE001 - e.g. "Flush timed out" with a dead viewer
            log.warning("rerun sink: flush failed: %s", exc)
            self._counters["errors"] += 1
        try:
            rec.disconnect()
        except Exception as exc:  # noqa: BLE001
            log.warning("rerun sink: disconnect failed: %s", exc)

    def _log(self, result: FusionResult) -> None:
        """Convert one result to Rerun archetypes and log it."""
        import rerun as rr

        rec, o, fr = self._recording(), self.options, result.frame
        root = self.context.rig
        rec.set_time("seq", sequence=int(fr.seq))
        if fr.stamp_ns:
            rec.set_time("stamp", timestamp=np.datetime64(int(fr.stamp_ns), "ns"))

        painted = o.log_painted and result.left_vpp is not None and result.right_vpp is not None
        left = result.left_vpp if painted else fr.left
        right = result.right_vpp if painted else fr.right
        rec.log(f"{root}/left", rr.Image(left))
        rec.log(f"{root}/right", rr.Image(right))

        disp = np.asarray(result.disparity, dtype=np.float32)
        sparse = fr.sparse_disparity
        rng = disparity_range(disp, sparse) or (0.0, 1.0)
        rec.log(f"{root}/disparity", rr.Image(colorize_disparity(disp, *rng)))

        if sparse is not None:
            ys, xs = np.nonzero(np.isfinite(sparse) & (sparse > 0))
            if ys.size > o.max_points:
                keep = np.linspace(0, ys.size - 1, o.max_points).astype(np.int64)
                ys, xs = ys[keep], xs[keep]
            vals = sparse[ys, xs]
            pos = np.stack([xs + 0.5, ys + 0.5], axis=1).astype(np.float32)
            rec.log(
                f"{root}/left/sparse",
                rr.Points2D(pos, colors=colorize_disparity(vals, *rng), radii=1.5),
            )

        if o.point_cloud and fr.calib is not None:
            depth = result.depth
            if depth is None:
                c = fr.calib
                with np.errstate(divide="ignore", invalid="ignore"):
                    depth = np.float32(c.f * c.baseline) / (disp + np.float32(c.doffs))
            depth = np.asarray(depth, dtype=np.float32)
            h, w = depth.shape
            s = depth_stride(h, w, o.max_points)
            dd = np.ascontiguousarray(depth[::s, ::s])
            dd[~(np.isfinite(dd) & (dd > 0))] = 0.0
            c = fr.calib
            # OpenCV convention (pixel centres at integers) for cx, cy; Rerun puts
            # pixel centres at +0.5, and decimated pixel i is original pixel s*i.
            cx = (w - 1) / 2.0 if c.cx is None else float(c.cx)
            cy = (h - 1) / 2.0 if c.cy is None else float(c.cy)
            rec.log(
                f"{root}/camera",
                rr.Pinhole(
                    focal_length=float(c.f) / s,
                    principal_point=[cx / s + 0.5, cy / s + 0.5],
                    width=dd.shape[1],
                    height=dd.shape[0],
                    camera_xyz=rr.ViewCoordinates.RDF,
                ),
            )
            rec.log(f"{root}/camera/depth", rr.DepthImage(dd, meter=1.0))

        for stage, ms in result.timing_ms.items():
            if isinstance(ms, (int, float)) and math.isfinite(ms) and _ENTITY_RE.match(str(stage)):
                rec.log(f"{root}/timing/{stage}", rr.Scalars(float(ms)))


__all__ = ["RerunSink", "RerunSinkOptions", "depth_stride"]
