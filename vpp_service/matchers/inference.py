"""Inference engines that run an ONNX stereo network: OpenVINO on CPU, ONNX Runtime on CPU or CUDA.

:func:`open_engine` picks and opens one; it keeps the few engines opened last
(a matcher rebuilt per scene or per disparity range reuses the loaded model).

* ``device = "cpu"``: OpenVINO when installed (the ``deep`` extra; the fastest
  measured on CPU), else ONNX Runtime's CPU provider.
* ``device = "cuda"``: ONNX Runtime's CUDA provider (the ``gpu`` extra,
  ``onnxruntime-gpu``, and a CUDA driver); an error when it cannot run there.
* ``device = "auto"``: CUDA when ONNX Runtime has a usable CUDA provider, else CPU.
* ``engine`` forces ``"openvino"`` or ``"onnxruntime"``.
* ``providers``: ONNX Runtime's execution providers in order of preference
  (``CUDAExecutionProvider``, ``TensorrtExecutionProvider``,
  ``OpenVINOExecutionProvider``, ``CPUExecutionProvider``...), each with its
  ``provider_options`` (a table per provider): ONNX Runtime then runs, on the
  device the first one drives (``"cuda"`` for CUDA and TensorRT). A provider
  this ONNX Runtime lacks is an error naming the ones it has.

Off the CPU, the inputs are copied to the device and the output bound there
(ONNX Runtime's IO binding): one copy each way per frame, no staging by the
session.

Precision: f32 unless asked otherwise. OpenVINO would silently run in bf16 on
a CPU with bf16 units when not told, so f32 is always set explicitly
(``INFERENCE_PRECISION_HINT``); ``"bf16"`` / ``"f16"`` are opt-in and only
OpenVINO honours them (ONNX Runtime runs the graph as exported, f32).
:attr:`Engine.precision` is what the engine reports it runs, read back after
compiling (a CPU without bf16 units runs f32 when bf16 is asked: logged as a
warning).
Threads: the project's policy (:func:`vpp_service.threads.resolve_threads`).

The engine packages are imported on first use; a missing one raises
:class:`EngineUnavailable` naming the extra to install.
"""

from __future__ import annotations

import json
import logging
import threading
from abc import ABC, abstractmethod
from collections import OrderedDict
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Literal

import numpy as np

from vpp_service.errors import StartupError

log = logging.getLogger(__name__)

Device = Literal["auto", "cpu", "cuda"]
EngineName = Literal["auto", "openvino", "onnxruntime"]
Precision = Literal["f32", "bf16", "f16"]

#: Tensor shape as the graph declares it: None for a dynamic dimension.
Shape = tuple[int | None, ...]

#: Engines kept open by :func:`open_engine` (the most recently used).
CACHE_SIZE = 2

_OV_PRECISION = {"f32": "f32", "bf16": "bf16", "f16": "f16"}

#: ONNX Runtime providers that run on an NVIDIA GPU (device ``"cuda"``: inputs and output bound there).
CUDA_PROVIDERS = ("CUDAExecutionProvider", "TensorrtExecutionProvider")


class EngineUnavailable(StartupError):
    """The engine a matcher needs is not installed or cannot run on the requested device."""


def _first_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split("\n")[:3]).strip()
    return (text[:300] + "...") if len(text) > 300 else (text or type(exc).__name__)


class Engine(ABC):
    """An opened network: its declared inputs and outputs, and :meth:`run`.

    Attributes
    ----------
    kind : str
        ``"openvino"`` or ``"onnxruntime"``.
    device : str
        Where it runs: ``"cpu"`` or ``"cuda"``.
    precision : str
        Inference precision in effect.
    threads : int
        Intra-op threads (CPU).
    inputs, outputs : dict of str to Shape
        Declared tensor shapes by name (None = dynamic dimension).
    """

    kind: str = ""

    def __init__(self, path: Path, device: str, precision: str, threads: int) -> None:
        self.path = path
        self.device = device
        self.precision = precision
        self.threads = threads
        self.inputs: dict[str, Shape] = {}
        self.outputs: dict[str, Shape] = {}
        self._lock = threading.Lock()

    def run(self, feeds: Mapping[str, np.ndarray], output: str) -> np.ndarray:
        """Run the network on ``feeds`` (input name -> float32 array) and return the ``output`` tensor.

        One call at a time per engine (calls from several threads wait for each other).

        Raises
        ------
        RuntimeError
            The engine failed on these inputs (one line, naming the model).
        """
        with self._lock:
            try:
                return self._run(feeds, output)
            except Exception as exc:  # noqa: BLE001 - engine errors come as many private types: one line naming the model
                raise RuntimeError(f"model {self.path.name}: {self.kind} failed: {_first_line(exc)}") from None

    @abstractmethod
    def _run(self, feeds: Mapping[str, np.ndarray], output: str) -> np.ndarray:
        """Engine-specific inference."""

    def describe(self) -> str:
        """``"openvino cpu f32, 2 threads"``."""
        return f"{self.kind} {self.device} {self.precision}, {self.threads} threads"


class OpenVINOEngine(Engine):
    """OpenVINO on CPU, the precision hint always set (f32 unless asked otherwise)."""

    kind = "openvino"

    def __init__(self, path: Path, precision: str, threads: int) -> None:
        super().__init__(path, "cpu", precision, threads)
        try:
            import openvino as ov
        except ImportError:
            raise EngineUnavailable("the OpenVINO engine is not installed: pip install 'vpp-service[deep]'") from None
        core = ov.Core()
        try:
            model = core.read_model(str(path))
            self._compiled = core.compile_model(
                model,
                "CPU",
                {
                    "INFERENCE_PRECISION_HINT": _OV_PRECISION[precision],
                    "INFERENCE_NUM_THREADS": threads,
                    "PERFORMANCE_HINT": "LATENCY",
                },
            )
        except Exception as exc:  # noqa: BLE001 - unsupported op, bad graph: OpenVINO raises RuntimeError and more
            raise ValueError(f"model {path.name}: OpenVINO cannot load it: {_first_line(exc)}") from None
        hint = self._compiled.get_property("INFERENCE_PRECISION_HINT")  # what the plugin really runs
        self.precision = hint.get_type_name() if hasattr(hint, "get_type_name") else str(hint)
        if self.precision != precision:  # e.g. bf16 asked on a CPU without bf16 units: OpenVINO runs f32
            log.warning(
                "model %s: precision %s asked, OpenVINO runs %s on this CPU", path.name, precision, self.precision
            )
        self.inputs = {n: _ov_shape(p) for p in model.inputs for n in p.get_names()}
        self.outputs = {n: _ov_shape(p) for p in model.outputs for n in p.get_names()}
        self._request = self._compiled.create_infer_request()

    def _run(self, feeds: Mapping[str, np.ndarray], output: str) -> np.ndarray:
        self._request.infer(dict(feeds))
        return np.array(self._request.get_tensor(output).data, copy=True)


def _ov_shape(port: Any) -> Shape:
    ps = port.get_partial_shape()
    if ps.rank.is_dynamic:
        return ()
    return tuple(d.get_length() if d.is_static else None for d in ps)


class OnnxRuntimeEngine(Engine):
    """ONNX Runtime on its CPU or CUDA provider, or the providers given (f32: the graph as exported).

    Attributes
    ----------
    providers : tuple of str
        The providers the session runs with, in order (what ONNX Runtime reports).
    """

    kind = "onnxruntime"

    def __init__(
        self,
        path: Path,
        device: str,
        precision: str,
        threads: int,
        *,
        providers: Sequence[str] = (),
        provider_options: Mapping[str, Mapping[str, Any]] | None = None,
    ) -> None:
        super().__init__(path, device, precision, threads)
        if precision != "f32":
            raise ValueError(
                f"precision {precision!r}: only the OpenVINO engine (CPU) runs reduced precision; "
                "ONNX Runtime runs the graph as exported (f32)"
            )
        ort = import_onnxruntime("cpu" if providers else device)  # providers: checked below, by name
        asked = list(providers) or ["CUDAExecutionProvider" if device == "cuda" else "CPUExecutionProvider"]
        check_providers(asked, ort.get_available_providers())
        options = [dict((provider_options or {}).get(p, {})) for p in asked]
        so = ort.SessionOptions()
        so.intra_op_num_threads = threads
        so.inter_op_num_threads = 1
        try:
            self._session = ort.InferenceSession(str(path), so, providers=asked, provider_options=options)
        except Exception as exc:  # noqa: BLE001 - ORT raises private pybind types (Fail, InvalidGraph, NotImplemented)
            raise ValueError(f"model {path.name}: ONNX Runtime cannot load it: {_first_line(exc)}") from None
        self.providers: tuple[str, ...] = tuple(self._session.get_providers())
        if self.providers[0] != asked[0]:
            raise EngineUnavailable(
                f"device {device!r}: ONNX Runtime could not start {asked[0]} "
                f"(it runs {list(self.providers)}; CUDA libraries or driver missing?)"
            )
        self.inputs = {i.name: _ort_shape(i.shape) for i in self._session.get_inputs()}
        self.outputs = {o.name: _ort_shape(o.shape) for o in self._session.get_outputs()}
        #: Where inputs and output are bound (IO binding): ``"cuda"`` off the CPU, None on it (plain run).
        self.bind_device: str | None = "cuda" if device == "cuda" else None
        self.device_id = int(options[0].get("device_id", 0)) if self.bind_device else 0
        self._ort = ort

    def _run(self, feeds: Mapping[str, np.ndarray], output: str) -> np.ndarray:
        if self.bind_device is None:
            return np.asarray(self._session.run([output], dict(feeds))[0])
        return self._run_bound(feeds, output, self.bind_device)

    def _run_bound(self, feeds: Mapping[str, np.ndarray], output: str, device: str) -> np.ndarray:
        """Run with the inputs copied to ``device`` and the output bound there (ONNX Runtime's IO binding)."""
        binding = self._session.io_binding()
        for name, arr in feeds.items():
            value = self._ort.OrtValue.ortvalue_from_numpy(np.ascontiguousarray(arr), device, self.device_id)
            binding.bind_ortvalue_input(name, value)
        binding.bind_output(output, device, self.device_id)
        self._session.run_with_iobinding(binding)
        return np.asarray(binding.copy_outputs_to_cpu()[0])


def check_providers(asked: Sequence[str], available: Sequence[str]) -> None:
    """Raise :class:`EngineUnavailable` naming the providers ``asked`` that ONNX Runtime lacks, and those it has."""
    missing = [p for p in asked if p not in available]
    if missing:
        raise EngineUnavailable(
            f"providers: this ONNX Runtime has no {', '.join(missing)}; it has {list(available)} "
            "(CUDA / TensorRT: pip install 'vpp-service[gpu]'; OpenVINO: onnxruntime-openvino)"
        )


def provider_device(providers: Sequence[str]) -> str:
    """The device the first of ``providers`` drives: ``"cuda"`` for CUDA and TensorRT, else ``"cpu"``."""
    return "cuda" if providers and providers[0] in CUDA_PROVIDERS else "cpu"


def _ort_shape(shape: Any) -> Shape:
    return tuple(d if isinstance(d, int) else None for d in (shape or ()))


def import_onnxruntime(device: str = "cpu") -> Any:
    """The ``onnxruntime`` module; for ``device="cuda"`` also check that it has the CUDA provider.

    Raises
    ------
    EngineUnavailable
        Not installed, or (cuda) installed without the CUDA provider; names the extra.
    """
    try:
        import onnxruntime as ort
    except ImportError:
        extra = "gpu" if device == "cuda" else "test"
        raise EngineUnavailable(
            f"ONNX Runtime is not installed: pip install 'vpp-service[{extra}]'"
            + (" (onnxruntime-gpu)" if device == "cuda" else " (or the 'deep' extra for OpenVINO)")
        ) from None
    if device == "cuda" and "CUDAExecutionProvider" not in ort.get_available_providers():
        raise EngineUnavailable(
            "device 'cuda': this ONNX Runtime has no CUDA provider: pip install 'vpp-service[gpu]' "
            "(onnxruntime-gpu, not onnxruntime) on a machine with a CUDA driver"
        )
    return ort


def _has(module: str) -> bool:
    import importlib.util

    return importlib.util.find_spec(module) is not None


def cuda_available() -> bool:
    """True when ONNX Runtime is installed with a CUDA provider (device ``"auto"`` then picks CUDA)."""
    if not _has("onnxruntime"):
        return False
    import onnxruntime as ort

    return "CUDAExecutionProvider" in ort.get_available_providers()


def choose(device: Device, engine: EngineName) -> tuple[str, str]:
    """The ``(engine, device)`` that ``device`` / ``engine`` resolve to (see the module docstring).

    Raises
    ------
    ValueError
        OpenVINO asked for CUDA.
    EngineUnavailable
        Nothing installed that runs there; names the extra.
    """
    if device == "auto":
        device = "cuda" if engine != "openvino" and cuda_available() else "cpu"
    if device == "cuda":
        if engine == "openvino":
            raise ValueError("engine 'openvino' runs on CPU only; device 'cuda' needs engine 'onnxruntime' or 'auto'")
        return "onnxruntime", "cuda"
    if engine != "auto":
        return engine, "cpu"
    if _has("openvino"):
        return "openvino", "cpu"
    if _has("onnxruntime"):
        return "onnxruntime", "cpu"
    raise EngineUnavailable(
        "no inference engine installed for a network matcher: pip install 'vpp-service[deep]' (OpenVINO, CPU) "
        "or 'vpp-service[gpu]' (ONNX Runtime, CUDA)"
    )


_cache: OrderedDict[tuple[object, ...], Engine] = OrderedDict()
_cache_lock = threading.Lock()


def open_engine(
    path: str | Path,
    device: Device = "auto",
    engine: EngineName = "auto",
    precision: Precision = "f32",
    threads: int = 1,
    *,
    providers: Sequence[str] = (),
    provider_options: Mapping[str, Mapping[str, Any]] | None = None,
) -> Engine:
    """Open (or reuse) the network at ``path`` on the chosen engine.

    Parameters
    ----------
    path : str or Path
        The ``.onnx`` file.
    device, engine, precision :
        See the module docstring.
    threads : int
        Intra-op threads (>= 1; resolved by the caller from the thread policy).
    providers, provider_options :
        ONNX Runtime's execution providers and their options (see the module
        docstring); given, they pick ONNX Runtime and the device.

    Returns
    -------
    Engine
        An engine kept in a small cache keyed by the file (path, size, mtime) and the settings.

    Raises
    ------
    FileNotFoundError
        No such file.
    ValueError
        The engine cannot load the graph (unsupported op, invalid file), or a bad combination of settings.
    EngineUnavailable
        The engine is not installed or cannot run on the device.
    """
    p = Path(path).expanduser()
    if not p.is_file():
        raise FileNotFoundError(f"model: no such file: {p}")
    if providers and (engine == "openvino" or device != "auto"):
        raise ValueError("providers: they choose ONNX Runtime and the device (leave engine and device 'auto')")
    kind, dev = ("onnxruntime", provider_device(providers)) if providers else choose(device, engine)
    st = p.stat()
    opts = json.dumps(provider_options or {}, sort_keys=True, default=str)
    key = (str(p.resolve()), st.st_size, st.st_mtime_ns, kind, dev, precision, threads, tuple(providers), opts)
    with _cache_lock:
        eng = _cache.get(key)
        if eng is not None:
            _cache.move_to_end(key)
            return eng
        eng = (
            OpenVINOEngine(p, precision, threads)
            if kind == "openvino"
            else OnnxRuntimeEngine(p, dev, precision, threads, providers=providers, provider_options=provider_options)
        )
        _cache[key] = eng
        while len(_cache) > CACHE_SIZE:
            _cache.popitem(last=False)
        return eng


def clear_cache() -> None:
    """Close every engine :func:`open_engine` keeps (their memory is freed once no matcher holds them)."""
    with _cache_lock:
        _cache.clear()


__all__ = [
    "CACHE_SIZE",
    "CUDA_PROVIDERS",
    "Device",
    "Engine",
    "EngineName",
    "EngineUnavailable",
    "OnnxRuntimeEngine",
    "OpenVINOEngine",
    "Precision",
    "check_providers",
    "choose",
    "clear_cache",
    "cuda_available",
    "import_onnxruntime",
    "open_engine",
    "provider_device",
]
