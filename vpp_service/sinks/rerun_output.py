"""Where the ``rerun`` sink's recording goes, and that place's life.

:class:`RerunOutput` owns the sink's :class:`rerun.RecordingStream` and what it
is attached to (the modes: :mod:`vpp_service.sinks.rerun`):

``save``
    The ``.rrd`` file, opened with the stream and rotated at ``max_mb``
    (:func:`~vpp_service.sinks.rotation.rotate`): every part is a complete
    recording (the blueprint and static data logged again).
``spawn``
    A native viewer started on ``grpc_port`` (after ``rerun analytics disable``
    unless ``analytics``).
``connect``
    A running viewer or server at ``url``.
``serve``
    A ``rerun --serve-grpc`` (``--serve-web``) child process on ``bind``, waited
    for until it listens and stopped at the end.

A viewer out of reach is probed every :data:`PROBE_INTERVAL_S` and reconnected
(blueprint and static data sent again) as soon as its port accepts connections.
What gets logged is :mod:`vpp_service.sinks.rerun_log`'s; when frames are
throttled or counted is the sink's.
"""

from __future__ import annotations

import importlib.util
import logging
import math
import shutil
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Literal, Protocol
from urllib.parse import urlsplit

from vpp_service.sinks.rerun_log import RerunLayout, RerunParts
from vpp_service.sinks.rotation import rotate

if TYPE_CHECKING:
    import rerun as rr
    import rerun.blueprint as rrb

log = logging.getLogger(__name__)

#: Rerun's default viewer URL (``connect`` with no ``url``).
DEFAULT_URL = "rerun+http://127.0.0.1:9876/proxy"
#: Seconds between two checks of an unreachable viewer's port.
PROBE_INTERVAL_S = 0.5
#: Longest wait for one frame to reach the viewer before it counts as undelivered.
FLUSH_TIMEOUT_S = 2.0


class OutputOptions(Protocol):
    """The sink options the output reads (:class:`~vpp_service.sinks.rerun.RerunSinkOptions` has them)."""

    @property
    def mode(self) -> Literal["save", "spawn", "connect", "serve"]:
        """``save``, ``spawn``, ``connect`` or ``serve``."""

    @property
    def path(self) -> str:
        """``save``: the ``.rrd`` file."""

    @property
    def max_mb(self) -> float:
        """``save``: rotate at this many megabytes; 0 = no cap."""

    @property
    def max_files(self) -> int:
        """``save`` with a cap: files kept, the current one included."""

    @property
    def url(self) -> str | None:
        """``connect``: the viewer's URL; None = Rerun's default."""

    @property
    def grpc_port(self) -> int:
        """``spawn``, ``serve``: the gRPC port."""

    @property
    def web_port(self) -> int:
        """``serve``: the web viewer's port; 0 = none."""

    @property
    def bind(self) -> str:
        """``serve``: the address listened on."""

    @property
    def memory_limit(self) -> str:
        """``spawn``, ``serve``: the viewer's / server's memory bound."""

    @property
    def analytics(self) -> bool:
        """``spawn``: leave the viewer's analytics as configured (else opt out first)."""


def _rerun_binary() -> list[str]:
    """Command that runs the Rerun CLI binary itself (not a wrapper that would outlive a kill)."""
    spec = importlib.util.find_spec("rerun_cli")
    if spec is not None and spec.origin:
        exe = Path(spec.origin).parent / "rerun"
        if exe.is_file():
            return [str(exe)]
    exe_path = shutil.which("rerun")
    return [exe_path] if exe_path else [sys.executable, "-m", "rerun_cli"]


def _disable_viewer_analytics() -> None:
    """Run ``rerun analytics disable`` (the viewer's own opt-out); log failures."""
    try:
        subprocess.run(
            [*_rerun_binary(), "analytics", "disable"],
            check=True,
            timeout=10,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
    except (OSError, subprocess.SubprocessError) as exc:
        log.warning("rerun sink: could not disable viewer analytics: %s", exc)


def reachable(url: str, timeout: float = 0.5) -> bool:
    """Whether a TCP connection to the host and port of a ``rerun+http://HOST:PORT/proxy`` URL succeeds."""
    parts = urlsplit(url.replace("rerun+", "", 1))
    try:
        socket.create_connection((parts.hostname or "127.0.0.1", parts.port or 9876), timeout=timeout).close()
    except OSError:
        return False
    return True


class RerunOutput:
    """The recording stream and the file or viewer it goes to (see the module docstring).

    Parameters
    ----------
    options : OutputOptions
        The sink's options (mode, file, viewer, server).
    layout : RerunLayout
        What is logged: the blueprint and the static data sent on every (re)attach.
    rig : str
        The entity-path root.
    count : callable
        ``count(name)``: adds one to the sink's counter ``name`` (``reconnects``,
        ``rotations``, ``errors``).
    """

    def __init__(self, options: OutputOptions, layout: RerunLayout, rig: str, count: Callable[[str], None]) -> None:
        self.options = options
        self.layout = layout
        self.rig = rig
        self._count = count
        self._rec: rr.RecordingStream | None = None
        self._url: str | None = None  # the viewer / server the network modes stream to
        self._connected = False
        self._last_probe = -math.inf
        self._server: subprocess.Popen[bytes] | None = None
        self._blueprint_sent = False
        #: ``serve``: the URL viewers connect to (None before the server runs).
        self.server_uri: str | None = None

    @property
    def opened(self) -> bool:
        """Whether :meth:`open` created the recording stream."""
        return self._rec is not None

    def blueprint(self) -> rrb.Blueprint:
        """The default :class:`rerun.blueprint.Blueprint` of the sink's views."""
        return self.layout.blueprint(self.rig)

    def _first_blueprint(self) -> rrb.Blueprint | None:
        """The blueprint when the 3-D view's framing is known (else it is sent with the first frame)."""
        if self.layout.depth_range is None and self.layout.point_cloud:
            return None
        self._blueprint_sent = True
        return self.blueprint()

    def open(self, application_id: str, recording_id: str) -> None:
        """Create the recording stream; ``save`` opens the file here (the network modes :meth:`attach` later).

        Raises
        ------
        FileNotFoundError
            ``save`` into a folder that does not exist.
        IsADirectoryError
            ``save`` to a folder.
        """
        import rerun as rr

        o = self.options
        self._rec = rec = rr.RecordingStream(application_id, recording_id=recording_id, send_properties=False)
        if o.mode == "save":
            path = Path(o.path).expanduser()
            if not path.parent.is_dir():
                raise FileNotFoundError(f"sinks.rerun.path: folder {str(path.parent)!r} does not exist")
            if path.is_dir():
                raise IsADirectoryError(f"sinks.rerun.path: {str(path)!r} is a folder, expected a .rrd file")
            rec.save(str(path), default_blueprint=self._first_blueprint())
            self.layout.log_static(rec, self.rig)

    def recording(self) -> rr.RecordingStream:
        """The recording stream; only the logging thread and :meth:`open` use it.

        Raises
        ------
        RuntimeError
            Before :meth:`open` created it.
        """
        if self._rec is None:
            raise RuntimeError("rerun sink: not open")
        return self._rec

    def attach(self) -> None:
        """Attach the network output (``spawn``, ``connect``, ``serve``; nothing for ``save``), on the logging thread.

        Raises
        ------
        RuntimeError
            ``serve``: the server did not start or does not accept connections.
        """
        o, rec, bp = self.options, self.recording(), self._first_blueprint()
        if o.mode == "spawn":
            if not o.analytics:
                _disable_viewer_analytics()
            rec.spawn(port=o.grpc_port, memory_limit=o.memory_limit, default_blueprint=bp)
            self._url = f"rerun+http://127.0.0.1:{o.grpc_port}/proxy"
            self._connected = True
            self.layout.log_static(rec, self.rig)
        elif o.mode == "connect":
            self._url = o.url or DEFAULT_URL
            if not self._reconnect():
                log.warning("rerun sink: no viewer at %s yet; frames count as undelivered until it is", self._url)
        elif o.mode == "serve":
            self._start_server()
            if not self._reconnect():
                raise RuntimeError(f"the Rerun server at {self._url} does not accept connections")

    def _start_server(self) -> None:
        """Start ``rerun --serve-grpc`` bound to ``bind`` (and the web viewer) and wait until it listens."""
        o = self.options
        host = f"[{o.bind}]" if ":" in o.bind else o.bind
        cmd = [
            *_rerun_binary(),
            "--serve-web" if o.web_port else "--serve-grpc",
            "--bind",
            o.bind,
            "--port",
            str(o.grpc_port),
            "--server-memory-limit",
            o.memory_limit,
        ]
        if o.web_port:
            cmd += ["--web-viewer-port", str(o.web_port)]
        self._server = subprocess.Popen(
            cmd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE
        )
        local = "127.0.0.1" if o.bind in ("0.0.0.0", "::") else host
        self._url = f"rerun+http://{local}:{o.grpc_port}/proxy"
        self.server_uri = f"rerun+http://{host}:{o.grpc_port}/proxy"
        deadline = time.monotonic() + 10.0
        while not reachable(self._url, 0.2):
            if self._server.poll() is not None:
                err = (self._server.stderr.read() if self._server.stderr else b"").decode(errors="replace")
                raise RuntimeError(f"rerun server exited ({self._server.returncode}): {err.strip()[-300:]}")
            if time.monotonic() > deadline:
                raise RuntimeError(f"rerun server did not listen on {o.bind}:{o.grpc_port} within 10 s")
            time.sleep(0.05)
        log.info(
            "rerun sink: serving %s%s", self.server_uri, f" (web viewer on {host}:{o.web_port})" * bool(o.web_port)
        )

    def _reconnect(self) -> bool:
        """(Re)connect to the viewer when its port accepts connections; True when connected."""
        self._last_probe = time.monotonic()
        if self._url is None or not reachable(self._url):
            return False
        rec = self.recording()
        rec.connect_grpc(self._url, default_blueprint=self._first_blueprint())
        self.layout.log_static(rec, self.rig)
        self._connected = True
        return True

    def send(self, parts: RerunParts) -> bool:
        """Log one frame's pieces to the file or the viewer; False when the viewer is out of reach (undelivered).

        ``save`` rotates the file first when it reached ``max_mb``; a viewer that was
        lost is probed (at most every :data:`PROBE_INTERVAL_S`) and reconnected.
        """
        if self.options.mode == "save":
            self._maybe_rotate()  # before logging: the newest file always holds the newest frame
            self._log(parts)
            if self.options.max_mb:
                self.recording().flush(timeout_sec=FLUSH_TIMEOUT_S)  # the file sink batches; the size must be current
            return True
        if not self._connected:
            if time.monotonic() - self._last_probe >= PROBE_INTERVAL_S and self._reconnect():
                self._count("reconnects")
                log.warning("rerun sink: reconnected to %s", self._url)
            else:
                return False
        self._log(parts)
        try:
            self.recording().flush(timeout_sec=FLUSH_TIMEOUT_S)
        except Exception as exc:  # noqa: BLE001 - "gRPC connection severed", "Flush timed out"
            self._connected = False
            self._last_probe = -math.inf
            log.warning("rerun sink: viewer at %s lost (%s); reconnecting when it is back", self._url, exc)
            return False
        return True

    def _log(self, parts: RerunParts) -> None:
        """Log one frame's pieces; send the blueprint again once the colour ranges are known."""
        self.layout.log(self.recording(), parts)
        if not self._blueprint_sent:
            self._blueprint_sent = True
            self.recording().send_blueprint(self.blueprint(), make_active=True, make_default=True)

    def _maybe_rotate(self) -> None:
        """``save`` with ``max_mb``: start a new file once the current one reached the cap."""
        o = self.options
        if not o.max_mb:
            return
        path = Path(o.path).expanduser()
        try:
            size = path.stat().st_size
        except OSError:
            return
        if size < o.max_mb * 1e6:
            return
        rec = self.recording()
        rotate(path, o.max_files)  # the file sink keeps writing to the renamed inode until save() below replaces it
        rec.save(str(path), default_blueprint=self._first_blueprint())
        self.layout.log_static(rec, self.rig)
        self._count("rotations")

    def flush_and_disconnect(self, deadline: float) -> None:
        """Flush what is logged (by ``deadline``, a ``time.monotonic()`` time, 5 s at most) and disconnect."""
        rec = self.recording()
        if self.options.mode == "save" or self._connected:
            try:
                rec.flush(timeout_sec=min(5.0, max(0.05, deadline - time.monotonic())))
            except Exception as exc:  # noqa: BLE001 - e.g. "Flush timed out" with a dead viewer
                log.warning("rerun sink: flush failed: %s", exc)
                self._count("errors")
        try:
            rec.disconnect()
        except Exception as exc:  # noqa: BLE001
            log.warning("rerun sink: disconnect failed: %s", exc)

    def stop_server(self) -> None:
        """``serve``: stop the server (terminate, kill after 2 s); nothing otherwise."""
        if self._server is None:
            return
        self._server.terminate()
        try:
            self._server.wait(timeout=2.0)
        except subprocess.TimeoutExpired:
            self._server.kill()
            self._server.wait()
        if self._server.stderr is not None:
            self._server.stderr.close()
        self._server = None


__all__ = ["DEFAULT_URL", "FLUSH_TIMEOUT_S", "PROBE_INTERVAL_S", "OutputOptions", "RerunOutput", "reachable"]
