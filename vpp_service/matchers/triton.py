"""The ``triton`` engine: a network served by NVIDIA Triton Inference Server (KServe v2 over gRPC).

The matcher keeps its card's pre- and post-processing on the client and sends
the tensors the card names (``left``, ``right``: ``1 x C x H x W`` of the
card's ``dtype``, or its ``concat_input``, and its ``extra_inputs``);
the server hosts the plain ``.onnx`` (ONNX Runtime or TensorRT backend,
``deploy/triton/``). No local model file is needed.

Servers: one ``host:port`` or several. Each request goes to the server with the
fewest outstanding requests; a server that cannot be reached or times out is
marked down, the request is re-sent to another one (counted ``retried``) and
the server is probed again after ``reprobe_s``. When no server is up a request
waits for one for up to ``retry_s`` and then fails (the frame is counted as an
error by the pipeline). A reply whose output is missing or is not FP32 / FP16 is
rejected (counted ``bad_replies``, a ValueError: the pipeline counts the frame
as rejected); a reply of the wrong shape is rejected by the matcher the same way.

Start-up (:meth:`TritonEngine.probe`): every server live and ready, the model
(and version) ready, and its metadata (tensor names, datatypes, ranks, channels)
agrees with the card, each disagreement one line naming both sides
(:func:`metadata_mismatches`).

The client library is ``tritonclient[grpc]`` (the ``triton`` extra), imported
on first use. Its gRPC client is thread-safe: up to ``in_flight`` frames are
matched at once by the pipeline's matcher stage, each request on its own thread.
"""

from __future__ import annotations

import atexit
import contextlib
import threading
import time
from collections import OrderedDict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from vpp_service.errors import StartupError
from vpp_service.matchers.inference import Engine, EngineUnavailable, Shape
from vpp_service.matchers.model_card import ModelCard

#: gRPC status codes of a server that could not reply (marked down, the request re-sent elsewhere).
TRANSPORT_CODES = frozenset({"StatusCode.UNAVAILABLE", "StatusCode.DEADLINE_EXCEEDED", "StatusCode.CANCELLED"})

#: KServe datatypes of the tensors sent (numpy dtype name -> datatype): the card's float32 / float16 images,
#: int64 or real extra inputs.
KSERVE_DTYPES = {"float32": "FP32", "float16": "FP16", "int64": "INT64", "int32": "INT32", "float64": "FP64"}

#: Engines kept open by :func:`open_triton` (their server health and counters are shared by matchers).
CACHE_SIZE = 4


class ServerUnavailable(StartupError):
    """No Triton server of the list could be reached (``run --check`` exits 2; ``run`` retries)."""


class ModelUnavailable(ServerUnavailable):
    """Servers reply but none is ready or has the model ready (it may be loading: ``run`` retries)."""


@dataclass(frozen=True)
class TritonSettings:
    """Where the network is served and how requests are sent.

    Attributes
    ----------
    urls : tuple of str
        ``host:port`` of each server's gRPC endpoint.
    model : str
        Model name on the server.
    model_version : str
        Version ("" = the server's policy, normally the latest).
    ssl : bool
        TLS to the servers; ``root_certificates``, ``private_key``,
        ``certificate_chain`` are PEM files ("" = none), as tritonclient takes them.
    timeout_ms : float
        Deadline of one request (a server that misses it is marked down).
    retry_s : float
        How long a request waits for a server when none is up.
    reprobe_s : float
        How long a server marked down is left alone before it is probed again.
    """

    urls: tuple[str, ...]
    model: str
    model_version: str = ""
    ssl: bool = False
    root_certificates: str = ""
    private_key: str = ""
    certificate_chain: str = ""
    timeout_ms: float = 30_000.0
    retry_s: float = 30.0
    reprobe_s: float = 1.0


def import_grpcclient() -> Any:
    """The ``tritonclient.grpc`` module.

    Raises
    ------
    EngineUnavailable
        Not installed; names the extra.
    """
    try:
        import tritonclient.grpc as grpcclient
    except ImportError:
        raise EngineUnavailable("the Triton client is not installed: pip install 'vpp-service[triton]'") from None
    return grpcclient


def _message(exc: BaseException) -> str:
    msg = getattr(exc, "message", None)
    text = msg() if callable(msg) else str(exc)
    text = " ".join(str(text).split())
    return (text[:300] + "...") if len(text) > 300 else (text or type(exc).__name__)


def _status(exc: BaseException) -> str:
    status = getattr(exc, "status", None)
    return str(status() if callable(status) else "") or ""


def _read(path: str) -> bytes | None:
    return Path(path).expanduser().read_bytes() if path else None


@dataclass
class _Server:
    """One server: its client, requests outstanding, and when it may be tried again if down."""

    url: str
    client: Any
    outstanding: int = 0
    down_until: float = 0.0
    error: str = ""
    replies: int = 0


class TritonEngine(Engine):
    """A network on one or several Triton servers (see the module docstring).

    Attributes
    ----------
    dtypes : dict of str to str
        KServe datatypes of the model's tensors (``"FP32"``), from its metadata.
    counters : dict of str to int
        ``requests``, ``answered`` (requests a server replied to), ``retried`` (re-sent after a server
        failed), ``bad_replies``, ``failed`` (no server replied), ``bytes_out`` / ``bytes_in`` (tensor
        bytes on the wire).
    """

    kind = "triton"

    def __init__(self, settings: TritonSettings) -> None:
        super().__init__(Path(settings.model), "remote", "f32", 0)
        if not settings.urls:
            raise ValueError("url: at least one Triton server (host:port) is required")
        self.settings = settings
        grpcclient = import_grpcclient()
        self._grpc = grpcclient
        try:
            certs = [_read(p) for p in (settings.root_certificates, settings.private_key, settings.certificate_chain)]
        except OSError as exc:
            raise FileNotFoundError(f"triton TLS file: {exc}") from None
        self._servers = [
            _Server(
                url,
                grpcclient.InferenceServerClient(
                    url=url,
                    ssl=settings.ssl,
                    root_certificates=certs[0],
                    private_key=certs[1],
                    certificate_chain=certs[2],
                ),
            )
            for url in settings.urls
        ]
        self.dtypes: dict[str, str] = {}
        self.counters = dict.fromkeys(
            ("requests", "answered", "retried", "bad_replies", "failed", "bytes_out", "bytes_in"), 0
        )
        self._cond = threading.Condition()
        self._known = False  # metadata read from a server

    # ------------------------------------------------------------ health
    def _check_server(self, server: _Server) -> dict[str, Any]:
        """Live, ready, model ready; the model's metadata. Raises with one line naming the server."""
        s, c, t = self.settings, server.client, min(self.settings.timeout_ms / 1e3, 10.0)
        where = f"triton server {server.url}"
        try:
            if not c.is_server_live(client_timeout=t):
                raise ModelUnavailable(f"{where}: not live")
            if not c.is_server_ready(client_timeout=t):
                raise ModelUnavailable(f"{where}: not ready")
            if not c.is_model_ready(s.model, s.model_version, client_timeout=t):
                version = f" version {s.model_version}" if s.model_version else ""
                listed = self._repository(c)
                raise ModelUnavailable(f"{where}: model {s.model!r}{version} is not ready (the server has: {listed})")
            meta: dict[str, Any] = c.get_model_metadata(s.model, s.model_version, as_json=True, client_timeout=t)
        except ModelUnavailable:
            raise
        except Exception as exc:  # noqa: BLE001 - InferenceServerException and gRPC errors: one line naming the server
            raise ConnectionError(f"{where}: unreachable: {_message(exc)}") from None
        return meta

    @staticmethod
    def _repository(client: Any) -> str:
        try:
            index = client.get_model_repository_index(as_json=True)
        except Exception:  # noqa: BLE001 - only for the message
            return "?"
        names = sorted(
            f"{m.get('name')}{'/' + m['version'] if m.get('version') else ''} ({m.get('state', '?').lower()})"
            for m in index.get("models", [])
        )
        return ", ".join(names) or "no models"

    def probe(self) -> list[str]:
        """Check every server; read the model's metadata (tensor shapes and datatypes).

        Returns
        -------
        list of str
            One line per server that is down (the others are used).

        Raises
        ------
        ServerUnavailable
            No server could be reached (one line naming each).
        ModelUnavailable
            No server has the model ready (or is ready at all), one line naming each.
        ValueError
            Servers disagree on the model's metadata.
        """
        down: list[str] = []
        metas: list[tuple[str, dict[str, Any]]] = []
        unready = False
        for server in self._servers:
            try:
                metas.append((server.url, self._check_server(server)))
                self._mark_up(server)
            except (ConnectionError, ModelUnavailable) as exc:
                unready |= isinstance(exc, ModelUnavailable)
                self._mark_down(server, str(exc))
                down.append(str(exc))
        if not metas:
            raise (ModelUnavailable if unready else ServerUnavailable)("; ".join(down))
        shapes = [(url, _shapes(meta)) for url, meta in metas]
        for url, other in shapes[1:]:
            if other != shapes[0][1]:
                raise ValueError(
                    f"triton model {self.settings.model!r}: servers disagree on its tensors: "
                    f"{shapes[0][0]} {shapes[0][1]}, {url} {other}"
                )
        self._set_metadata(metas[0][1])
        return down

    def _set_metadata(self, meta: Mapping[str, Any]) -> None:
        (self.inputs, self.outputs), self.dtypes = _shapes(meta), _dtypes(meta)
        self._known = True

    def _mark_down(self, server: _Server, error: str) -> None:
        with self._cond:
            server.down_until = time.monotonic() + self.settings.reprobe_s
            server.error = error

    def _mark_up(self, server: _Server) -> None:
        with self._cond:
            server.down_until, server.error = 0.0, ""
            self._cond.notify_all()

    def ensure_metadata(self) -> None:
        """Read the model's metadata if no server has given it yet, retrying for up to ``retry_s``.

        Raises
        ------
        RuntimeError
            No server replied within ``retry_s`` (the next frame tries again).
        """
        if self._known:
            return
        deadline = time.monotonic() + self.settings.retry_s
        while True:
            try:
                self.probe()
                return
            except ServerUnavailable as exc:
                if time.monotonic() >= deadline:
                    raise RuntimeError(f"model {self.settings.model}: {exc}") from None
            time.sleep(min(self.settings.reprobe_s, max(0.0, deadline - time.monotonic())))

    # ----------------------------------------------------------- requests
    def _acquire(self, deadline: float, avoid: set[str]) -> _Server | None:
        """The up server with the fewest outstanding requests (probing those due); None past ``deadline``."""
        while True:
            now = time.monotonic()
            with self._cond:
                up = [s for s in self._servers if s.down_until <= now and s.url not in avoid]
                if not up:
                    up = [s for s in self._servers if s.down_until <= now]
                if up:
                    best = min(up, key=lambda s: s.outstanding)
                    best.outstanding += 1
                    return best
                if not self._servers:  # closed
                    return None
                wake = min(s.down_until for s in self._servers)
            if now >= deadline:
                return None
            time.sleep(max(0.005, min(wake, deadline) - now))

    def _release(self, server: _Server) -> None:
        with self._cond:
            server.outstanding -= 1

    def _count(self, key: str, n: int = 1) -> None:
        with self._cond:
            self.counters[key] += n

    def run(self, feeds: Mapping[str, np.ndarray], output: str) -> np.ndarray:
        """Send ``feeds`` to a server and return its ``output`` tensor (float32, the shape the server sent).

        Many calls may run at once (one per frame in flight); each gets one reply.

        Raises
        ------
        RuntimeError
            No server replied within ``retry_s``, or the server refused the request (one line).
        ValueError
            The reply lacks ``output`` or it is not FP32 / FP16 (counted ``bad_replies``).
        """
        self.ensure_metadata()
        g, s = self._grpc, self.settings
        inputs = []
        sent = 0
        for name, arr in feeds.items():
            a = np.ascontiguousarray(arr)
            inp = g.InferInput(name, list(a.shape), KSERVE_DTYPES.get(a.dtype.name, "FP32"))
            inp.set_data_from_numpy(a)
            inputs.append(inp)
            sent += a.nbytes
        outputs = [g.InferRequestedOutput(output)]
        self._count("requests")
        deadline = time.monotonic() + s.retry_s
        tried: set[str] = set()
        while True:
            server = self._acquire(deadline, tried)
            if server is None:
                self._count("failed")
                errors = "; ".join(sorted({x.error for x in self._servers if x.error})) or "no server up"
                raise RuntimeError(f"model {s.model}: no Triton server replied within {s.retry_s:g} s: {errors}")
            if tried:
                self._count("retried")
            tried.add(server.url)
            try:
                result = server.client.infer(
                    s.model, inputs, model_version=s.model_version, outputs=outputs, client_timeout=s.timeout_ms / 1e3
                )
            except Exception as exc:  # noqa: BLE001 - InferenceServerException (gRPC status inside) and gRPC errors
                self._release(server)
                if _status(exc) in TRANSPORT_CODES or not _status(exc):
                    self._mark_down(server, f"{server.url}: {_message(exc)}")
                    continue
                self._count("failed")
                raise RuntimeError(f"model {s.model}: triton server {server.url} refused: {_message(exc)}") from None
            self._release(server)
            with self._cond:
                server.replies += 1
            self._count("bytes_out", sent)
            return self._output(result, output, server.url)

    def _output(self, result: Any, output: str, url: str) -> np.ndarray:
        """The reply's ``output`` (FP32 or FP16) as float32, or a counted ValueError."""
        meta = result.get_output(output)
        if meta is None:
            self._count("bad_replies")
            raise ValueError(f"model {self.settings.model}: the reply of {url} has no output {output!r}")
        if meta.datatype not in ("FP32", "FP16"):
            self._count("bad_replies")
            raise ValueError(
                f"model {self.settings.model}: the reply of {url} has output {output!r} as {meta.datatype}, "
                "expected FP32 (or FP16)"
            )
        try:
            arr = result.as_numpy(output)
        except Exception as exc:  # noqa: BLE001 - a malformed payload (size does not match the shape)
            self._count("bad_replies")
            raise ValueError(f"model {self.settings.model}: the reply of {url} is malformed: {_message(exc)}") from None
        self._count("answered")
        self._count("bytes_in", int(arr.nbytes))
        return np.asarray(arr, dtype=np.float32)

    def bad_reply(self) -> None:
        """Count a reply the matcher rejected (wrong shape for the request)."""
        self._count("bad_replies")

    def _run(self, feeds: Mapping[str, np.ndarray], output: str) -> np.ndarray:  # pragma: no cover - run overrides
        return self.run(feeds, output)

    def status(self) -> dict[str, Any]:
        """Counters and each server's state (``outstanding``, ``answered``: its replies, ``down``, ``error``)."""
        now = time.monotonic()
        with self._cond:
            servers = {
                s.url: {
                    "outstanding": s.outstanding,
                    "answered": s.replies,
                    "down": s.down_until > now,
                    "error": s.error,
                }
                for s in self._servers
            }
            return {**self.counters, "servers": servers}

    def describe(self) -> str:
        """``"triton psmnet_kitti2015 on 2 servers (a:8001, b:8001)"``."""
        version = f" v{self.settings.model_version}" if self.settings.model_version else ""
        n, urls = len(self._servers), ", ".join(self.settings.urls)
        return f"triton {self.settings.model}{version} on {n} server{'s' if n > 1 else ''} ({urls})"

    def close(self) -> None:
        """Close the gRPC channels and let the clients go (the engine takes no requests after this)."""
        servers, self._servers = self._servers, []
        for server in servers:
            with contextlib.suppress(Exception):  # closing a dead channel
                server.client.close()


def _shape(dims: Sequence[Any]) -> Shape:
    return tuple(None if int(d) < 0 else int(d) for d in dims)


def _shapes(meta: Mapping[str, Any]) -> tuple[dict[str, Shape], dict[str, Shape]]:
    ins = {t["name"]: _shape(t.get("shape", ())) for t in meta.get("inputs", [])}
    outs = {t["name"]: _shape(t.get("shape", ())) for t in meta.get("outputs", [])}
    return ins, outs


def _dtypes(meta: Mapping[str, Any]) -> dict[str, str]:
    return {t["name"]: str(t.get("datatype", "")) for t in [*meta.get("inputs", []), *meta.get("outputs", [])]}


def metadata_mismatches(engine: TritonEngine, card: ModelCard, output: str) -> list[str]:
    """Where the served model's metadata and ``card`` disagree: one line each, naming both sides.

    ``output`` is the output the matcher reads ("" = the model's only output).
    """
    model = f"triton model {engine.settings.model!r}"
    lines: list[str] = []
    ins, outs, dtypes = engine.inputs, engine.outputs, engine.dtypes
    want = KSERVE_DTYPES[card.dtype]
    for key in ("concat_input",) if card.concat_input else ("left_input", "right_input"):
        name = getattr(card, key)
        if name not in ins:
            lines.append(f"card {key} {name!r}: {model} has no such input (its inputs: {sorted(ins)})")
            continue
        shape = ins[name]
        if dtypes.get(name) != want:
            lines.append(f"card {key} {name!r} is {card.dtype} ({want}): {model} takes {dtypes.get(name)}")
        if len(shape) != 4:
            lines.append(f"card {key} {name!r} is 1 x C x H x W (rank 4): {model} takes rank {len(shape)} {shape}")
            continue
        if shape[1] is not None and shape[1] != card.input_channels:
            lines.append(
                f"card {key} {name!r} has {card.input_channels} channels (colour {card.colour}): "
                f"{model} takes {shape[1]}"
            )
        hw = shape[2:]
        if card.fixed and any(v is not None for v in hw) and tuple(hw) != tuple(card.input_size):
            lines.append(f"card input_size {list(card.input_size)}: {model} input {name!r} is {hw[0]} x {hw[1]}")
        if not card.fixed and all(v is not None for v in hw):
            lines.append(f"card input_size [] (dynamic): {model} input {name!r} is fixed at {hw[0]} x {hw[1]}")
    lines += [
        f"card extra_inputs {name!r}: {model} has no such input (its inputs: {sorted(ins)})"
        for name in sorted(set(card.extra_inputs) - set(ins))
    ]
    fed = [*card.image_inputs, *card.extra_inputs]
    extra = sorted(set(ins) - set(fed))
    if extra:
        lines.append(f"card feeds {fed}: {model} also takes {extra}")
    if output and output not in outs:
        lines.append(f"card output {output!r}: {model} has no such output (its outputs: {sorted(outs)})")
    elif not output and len(outs) != 1:
        lines.append(f"card output '' (the only output): {model} has outputs {sorted(outs)}")
    else:
        name = output or next(iter(outs))
        if dtypes.get(name) != want:
            lines.append(f"card output {name!r} is {card.dtype} ({want}): {model} gives {dtypes.get(name)}")
        rank = len(outs[name])
        if rank != len(card.output_layout):
            lines.append(
                f"card output_layout {card.output_layout!r} (rank {len(card.output_layout)}): "
                f"{model} output {name!r} has rank {rank}"
            )
    return lines


_cache: OrderedDict[TritonSettings, TritonEngine] = OrderedDict()
_cache_lock = threading.Lock()


def open_triton(settings: TritonSettings) -> TritonEngine:
    """The engine for ``settings`` (kept: matchers of the same settings share servers' health and counters).

    Raises
    ------
    EngineUnavailable
        ``tritonclient`` is not installed.
    FileNotFoundError
        A TLS file is missing.
    """
    with _cache_lock:
        eng = _cache.get(settings)
        if eng is not None:
            _cache.move_to_end(settings)
            return eng
        eng = TritonEngine(settings)
        _cache[settings] = eng
        while len(_cache) > CACHE_SIZE:
            _cache.popitem(last=False)[1].close()
        return eng


def close_all() -> None:
    """Close every cached engine (at exit: a gRPC client left to the interpreter's teardown fails in ``__del__``)."""
    with _cache_lock:
        engines = list(_cache.values())
        _cache.clear()
    for eng in engines:
        eng.close()


atexit.register(close_all)


__all__ = [
    "ModelUnavailable",
    "ServerUnavailable",
    "TritonEngine",
    "TritonSettings",
    "close_all",
    "import_grpcclient",
    "metadata_mismatches",
    "open_triton",
]
