"""The ``rerun`` sink: stream results to a Rerun viewer, server or ``.rrd`` file.

What is logged and the default layout: :mod:`vpp_service.sinks.rerun_log`; the
recording stream and where it goes (the file and its rotation, the viewer spawned,
connected to or served, reconnects): :mod:`vpp_service.sinks.rerun_output`. This
module is the sink: its options, the throttle, the write path and the counts.

Modes
-----
``save``
    Write a ``.rrd`` recording to ``path`` (open it later with ``rerun vpp.rrd``).
    With ``max_mb > 0`` the file is rotated when it reaches that size:
    ``vpp.rrd`` is always the newest, older parts are ``vpp.1.rrd`` (newer) ...
    ``vpp.<max_files - 1>.rrd``; older parts are deleted. Every part is a
    complete recording (same recording id, the blueprint and static data).
``spawn``
    Start a local native viewer listening on ``grpc_port`` and stream to it
    (``memory_limit`` bounds the viewer's memory; oldest data is dropped).
``connect``
    Stream to a running viewer/server at ``url`` (default
    ``rerun+http://127.0.0.1:9876/proxy``).
``serve``
    Host a gRPC server on ``bind:grpc_port`` (a ``rerun --serve-grpc`` child
    process; default ``127.0.0.1``, i.e. this machine only) that buffers up to
    ``memory_limit`` for late viewers (``rerun rerun+http://HOST:PORT/proxy``);
    with ``web_port > 0`` a web viewer is also served on ``bind:web_port``.
    Neither is authenticated: bind another address only on a trusted network.

Delivery (``spawn``, ``connect``, ``serve``)
--------------------------------------------
Each frame is flushed to the viewer before the next one is logged, so at most
``queue_size`` frames wait in the sink and one is in flight: the memory is
bounded even with no viewer. When the viewer is unreachable (never started,
closed, restarting) frames are not logged and are counted as ``undelivered``;
the sink checks the viewer's port every 0.5 s and reconnects (new connection,
blueprint and static data re-sent) as soon as it is back.

Threading and back-pressure
---------------------------
:meth:`RerunSink.write` applies the ``max_hz`` throttle, converts and logs,
synchronously. The pipeline runs it on this sink's own thread behind a queue of
``queue_size`` results (:meth:`RerunSink.queue_spec`: drop-oldest, or waiting
for room under the pipeline's ``block`` output policy, a replay), and calls
:meth:`RerunSink.start` (attach) and :meth:`RerunSink.finish` (flush,
disconnect) on that thread. Throttled frames are counted (``throttled``:
skipped on purpose, not a loss) and said once in the log; ``undelivered`` is
``dropped``. The sink uses its own
:class:`rerun.RecordingStream` (never the global one), with per-rig ids
(application ``vpp-service-<rig>``, recording ``<rig>-<uuid>``) so that several
rigs coexist in one viewer, and sets the time per frame on the ``seq``
(sequence) and ``stamp`` (timestamp) timelines.

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
import threading
import time
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Literal

from vpp_service.frame import FusionResult
from vpp_service.settings import Matches, NonEmpty, Options, Range, Satisfies, reject
from vpp_service.sinks.base import SINKS, QueueSpec, Sink, SinkContext
from vpp_service.sinks.rerun_log import ENTITY_RE, RerunLayout, RerunParts, depth_stride, parts_from_result
from vpp_service.sinks.rerun_output import RerunOutput, reachable
from vpp_service.sinks.rotation import rotated_paths
from vpp_service.transport.backproject import DEFAULT_STRIDE, MAX_STRIDE

if TYPE_CHECKING:
    import rerun.blueprint as rrb

log = logging.getLogger(__name__)

_MEMORY_RE = re.compile(r"^\s*(\d+(\.\d+)?)\s*(B|KB|MB|GB|TB|KiB|MiB|GiB|TiB)\s*$|^\s*(\d+(\.\d+)?)\s*%\s*$")
_URL_RE = re.compile(r"^rerun(\+https?)?://[^/\s]+/proxy$")
#: ``max_hz`` when the option is None and the sink streams to a viewer (a 10 Hz camera is never throttled).
VIEWER_MAX_HZ = 15.0
#: Frames the throttle's token bucket holds: a burst this long passes (a camera's jitter is not throttled).
THROTTLE_BURST = 2.0


def _is_range(value: list[float]) -> bool:
    """Whether ``value`` is ``[min, max]`` of finite numbers with ``min < max``."""
    return (
        isinstance(value, (list, tuple))
        and len(value) == 2
        and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)
        and value[1] > value[0]
    )


#: Markers of the rerun sink's options.
_RANGE = Satisfies(_is_range, "[min, max] with finite min < max")
_NAME = NonEmpty()


@dataclass(frozen=True)
class RerunSinkOptions(Options):
    """Options of the ``rerun`` sink.

    Attributes
    ----------
    mode : {"save", "spawn", "connect", "serve"}
        Where the data goes (see the module docstring). Default ``"save"``.
    path : str
        ``.rrd`` file for ``save`` (default ``"vpp.rrd"``; parent must exist).
    max_mb : float
        ``save``: rotate the file when it reaches this many megabytes (10^6 bytes);
        0 = no cap. Default 1000.
    max_files : int
        ``save`` with a cap: files kept, the current one included (>= 1).
    url : str or None
        gRPC URL for ``connect`` (``rerun+http://HOST:PORT/proxy``); None =
        Rerun's default ``rerun+http://127.0.0.1:9876/proxy``.
    grpc_port : int
        Port of the spawned viewer (``spawn``) or of the served gRPC server
        (``serve``). Default 9876.
    web_port : int
        ``serve`` only: also host the web viewer on this port; 0 = no web viewer.
    bind : str
        ``serve`` only: address the gRPC server and the web viewer listen on;
        default ``127.0.0.1`` (this machine only); ``0.0.0.0`` = every interface.
    max_hz : float or None
        At most this many frames per second on average are logged (a token bucket
        holding two frames absorbs a camera's jitter); 0 = every frame. None (the
        default): every frame when saving to a file, at most 15/s to a viewer
        (``spawn``, ``connect``, ``serve``). Frames over the cap are counted as
        ``throttled``, apart from losses.
    memory_limit : str
        Memory bound of the spawned viewer / the gRPC server buffer, e.g.
        ``"512MB"``, ``"2GiB"``, ``"25%"``.
    queue_size : int
        Frames waiting for this sink's thread in the pipeline (>= 1); when full
        the oldest is dropped and counted (unless the pipeline blocks).
    log_painted : bool
        Log the painted pair (when present) instead of the raw pair.
    jpeg_quality : int
        JPEG quality of the logged pair, 1..100; 0 = uncompressed. Default 85.
    disparity_range : list of float or None
        ``[min, max]`` pixels of the disparity colour map; None = from the first frame.
    depth_range : list of float or None
        ``[min, max]`` metres of the depth colour map (farther points are not
        drawn in 3-D); None = from the first frame.
    sparse_points : bool
        Log the sparse input points over the left image.
    max_sparse_points : int
        Most sparse points logged per frame (>= 1).
    point_cloud : bool
        Log pinhole + depth image for the 3-D view.
    confidence : bool
        Log the per-pixel confidence of the disparity (``<rig>/confidence``, 0..1);
        the service computes it only then (for matchers other than census-sgm a
        second matching pass).
    max_points : int
        Upper bound of logged depth pixels (the depth image is decimated by an
        integer stride).
    points : bool
        Also log the point cloud as ``rr.Points3D`` (``<rig>/points``, in the camera's
        frame beside the pinhole, coloured from the left image); off by default: the
        depth image already draws an uncoloured cloud.
    points_stride : int
        ``points``: every ``points_stride``-th row and column of the depth map (1 = every
        pixel; the default 4 keeps a 720p cloud under 57 600 points).
    application_id : str or None
        Rerun application id (the viewer groups recordings and keeps one
        blueprint per id); None = ``vpp-service-<rig>``.
    recording_id : str or None
        Rerun recording id; None = ``<rig>-<random uuid>``.
    analytics : bool
        Leave the spawned viewer's usage analytics as configured (true) or
        opt out before spawning (false, default).
    """

    mode: Literal["save", "spawn", "connect", "serve"] = "save"
    path: Annotated[str, NonEmpty()] = "vpp.rrd"
    max_mb: Annotated[float, Range(0.0)] = 1000.0
    max_files: Annotated[int, Range(1)] = 3
    url: Annotated[str | None, Matches(_URL_RE.pattern, "rerun+http://HOST:PORT/proxy")] = None
    grpc_port: Annotated[int, Range(1, 65535)] = 9876
    web_port: Annotated[int, Range(0, 65535)] = 0
    bind: Annotated[str, Matches(r"\S+", "an IP address such as 127.0.0.1")] = "127.0.0.1"
    max_hz: Annotated[float | None, Range(0.0)] = None
    memory_limit: Annotated[str, Matches(_MEMORY_RE.pattern, "a size like '512MB', '2GiB' or '25%'")] = "512MB"
    queue_size: Annotated[int, Range(1)] = 2
    log_painted: bool = True
    jpeg_quality: Annotated[int, Range(0, 100)] = 85
    disparity_range: Annotated[list[float] | None, _RANGE] = None
    depth_range: Annotated[list[float] | None, _RANGE] = None
    sparse_points: bool = True
    max_sparse_points: Annotated[int, Range(1)] = 5000
    point_cloud: bool = True
    confidence: bool = False
    max_points: Annotated[int, Range(1)] = 200_000
    points: bool = False
    points_stride: Annotated[int, Range(1, MAX_STRIDE)] = DEFAULT_STRIDE
    application_id: Annotated[str | None, _NAME] = None
    recording_id: Annotated[str | None, _NAME] = None
    analytics: bool = False

    def cross_check(self) -> None:
        """The viewer's web port apart from its gRPC port."""
        if self.web_port and self.web_port == self.grpc_port:
            raise reject("web_port", self.web_port, f"0 or a port other than grpc_port ({self.grpc_port})")


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

    @classmethod
    def needs_confidence(cls, options: RerunSinkOptions) -> bool:
        """True when the sink logs the confidence (``confidence``)."""
        return options.confidence

    def __init__(self, options: RerunSinkOptions, context: SinkContext | None = None) -> None:
        if not isinstance(options, RerunSinkOptions):
            raise TypeError(f"options: must be RerunSinkOptions, got {type(options).__name__}")
        context = context or SinkContext()
        if not ENTITY_RE.match(context.rig):
            raise ValueError(f"context.rig: must be letters, digits, '_', '-', '.', got {context.rig!r}")
        super().__init__(options, context)
        self._counters.update({"throttled": 0, "undelivered": 0, "reconnects": 0, "rotations": 0})
        self._state: Literal["new", "open", "finished", "closed"] = "new"
        o = options
        self.layout = RerunLayout(
            jpeg_quality=o.jpeg_quality,
            disparity_range=None if o.disparity_range is None else (o.disparity_range[0], o.disparity_range[1]),
            depth_range=None if o.depth_range is None else (o.depth_range[0], o.depth_range[1]),
            max_points=o.max_points,
            max_sparse_points=o.max_sparse_points if o.sparse_points else 0,
            point_cloud=o.point_cloud,
            points=o.points,
            points_stride=o.points_stride,
            confidence=o.confidence,
        )
        self.application_id = o.application_id or f"vpp-service-{context.rig}"
        #: The recording stream and the file or viewer it goes to.
        self.output = RerunOutput(o, self.layout, context.rig, self.count)
        self._last_accept = time.monotonic()
        self._tokens = THROTTLE_BURST  # the throttle's token bucket (frames that may be logged now)
        self._ready = threading.Event()
        self._close_deadline = math.inf
        self._said_throttle = False

    @property
    def server_uri(self) -> str | None:
        """``serve``: the URL viewers connect to (None before the server runs)."""
        return self.output.server_uri

    # -- life cycle -----------------------------------------------------------------
    def blueprint(self) -> rrb.Blueprint:
        """The default :class:`rerun.blueprint.Blueprint` of the sink's views."""
        return self.output.blueprint()

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
        if self._state != "new":
            raise RuntimeError("rerun sink: already open")
        o = self.options
        self.output.open(self.application_id, o.recording_id or f"{self.context.rig}-{uuid.uuid4()}")
        if o.mode == "save":
            self._ready.set()
        self._state = "open"

    def queue_spec(self) -> QueueSpec:
        """``queue_size`` results wait for this sink (a full queue drops the oldest unless the pipeline blocks)."""
        return QueueSpec(size=self.options.queue_size)

    def start(self) -> None:
        """Attach the network output (spawn, connect, serve), on the thread that logs."""
        self._attach_once()

    def finish(self) -> None:
        """Flush and disconnect, on the thread that logs."""
        if self._state != "open":
            return
        self._state = "finished"
        self.output.flush_and_disconnect(self._close_deadline)

    def wait_ready(self, timeout: float = 5.0) -> bool:
        """Attach the output now if :meth:`start` has not (the server runs, the viewer is spawned).

        Returns
        -------
        bool
            True when attached (or attaching failed and was counted in
            ``stats()["errors"]``), False when not open.
        """
        if self._state != "open":
            return False
        self._attach_once()
        return self._ready.wait(timeout)

    def write(self, result: FusionResult) -> None:
        """Log ``result`` (throttled by ``max_hz``), synchronously.

        Raises
        ------
        TypeError
            If ``result`` is not a FusionResult.
        RuntimeError
            If the sink is not open.
        """
        if not isinstance(result, FusionResult):
            raise TypeError(f"result: must be a FusionResult, got {type(result).__name__}")
        self._check_open()
        self._accept(result)

    @property
    def max_hz(self) -> float:
        """The effective ``max_hz``: the option, else 0 (every frame) for ``save`` and 15 for a viewer."""
        o = self.options
        if o.max_hz is not None:
            return o.max_hz
        return 0.0 if o.mode == "save" else VIEWER_MAX_HZ

    def _accept(self, result: FusionResult) -> None:
        """Throttle (``max_hz``, a two-frame token bucket) and queue one result."""
        hz = self.max_hz
        if hz > 0:
            now = time.monotonic()
            self._tokens = min(THROTTLE_BURST, self._tokens + (now - self._last_accept) * hz)
            self._last_accept = now
            if self._tokens < 1.0:
                self._counters["throttled"] += 1
                if not self._said_throttle:
                    self._said_throttle = True
                    log.info(
                        "rerun sink: logging at most %g frames/s (max_hz); the others are skipped and counted "
                        "as 'throttled', not lost (max_hz = 0 logs every frame)",
                        hz,
                    )
                return
            self._tokens -= 1.0
        self._log_item(result)

    def submit(self, parts: RerunParts) -> None:
        """Log already split pieces (``vpp-service view``), synchronously; no ``max_hz`` throttle.

        Raises
        ------
        TypeError
            If ``parts`` is not a RerunParts.
        RuntimeError
            If the sink is not open.
        """
        if not isinstance(parts, RerunParts):
            raise TypeError(f"parts: must be RerunParts, got {type(parts).__name__}")
        self._check_open()
        self._log_item(parts)

    def _check_open(self) -> None:
        if self._state != "open":
            raise RuntimeError("rerun sink: write() before open() or after close()")

    def _log_item(self, item: FusionResult | RerunParts) -> None:
        """Log one frame (attaching first if needed); a frame that cannot be logged is counted, never raised."""
        self._attach_once()
        try:
            self._log_one(item)
        except Exception as exc:  # noqa: BLE001 - a bad frame must not kill the sink
            self._failed(item, exc)

    def close(self, timeout: float = 5.0) -> None:
        """Flush and disconnect (unless :meth:`finish` did) within about ``timeout`` seconds, stop a server.

        The flush is bounded by ``timeout``; a library call that hangs anyway is bounded by the
        pipeline, which abandons the close (:class:`~vpp_service.service.pipeline.Pipeline`).
        """
        if self._state in ("new", "closed"):
            return
        self._close_deadline = time.monotonic() + max(0.0, float(timeout))
        self.finish()
        self._state = "closed"
        self.output.stop_server()
        st = self.stats()
        if st["dropped"] or st["throttled"]:
            log.info(
                "rerun sink: logged %d frames; not logged: %d over max_hz, %d undelivered",
                st["written"],
                st["throttled"],
                st["undelivered"],
            )

    def stats(self) -> dict[str, int]:
        """Counters: ``written``, ``errors``, ``throttled``, ``undelivered``, ``dropped``.

        ``dropped`` (a loss) is ``undelivered`` (a viewer out of reach); ``throttled`` frames (over
        ``max_hz``) were skipped on purpose and are not in it. Results dropped from the queue in front
        of this sink are the pipeline's to count (``sink.RerunSink``).

        Also ``reconnects`` (network modes) and ``rotations`` (``save`` with ``max_mb``).
        """
        out = super().stats()
        out["dropped"] = out["undelivered"]  # throttled frames were skipped on purpose
        return out

    # -- logging thread -------------------------------------------------------------
    def _attach_once(self) -> None:
        if self._ready.is_set() or not self.output.opened:
            return
        try:
            self.output.attach()
        except Exception as exc:  # noqa: BLE001 - reported via stats and log
            log.error("rerun sink: cannot attach %s output: %s", self.options.mode, exc)
            self._counters["errors"] += 1
        self._ready.set()

    def _log_one(self, item: FusionResult | RerunParts) -> None:
        parts = parts_from_result(item, self.options.log_painted) if isinstance(item, FusionResult) else item
        self.count("written" if self.output.send(parts) else "undelivered")

    def _failed(self, item: FusionResult | RerunParts, exc: Exception) -> None:
        # a bad frame must not kill the sink
        seq = item.frame.seq if isinstance(item, FusionResult) else item.seq
        log.warning("rerun sink: cannot log frame %s: %s", seq, exc)
        self._counters["errors"] += 1


__all__ = ["RerunSink", "RerunSinkOptions", "depth_stride", "reachable", "rotated_paths"]
