"""Real Triton Inference Servers for the tests: the ``tritonserver`` binary of the ``nvidia-pytriton`` wheel.

* :func:`server_venv` - the server's own venv (``nvidia-pytriton`` without its
  dependencies, ``numpy<2`` for its Python-backend stub, ``onnxruntime``),
  built once under ``~/.cache/vpp-service-tests/`` (keyed by
  :data:`VENV_KEY`) and reused by every later run, CI's fresh clones included;
  ``$VPP_TEST_TRITON_VENV`` names another folder. Never the project's venv:
  the stub needs numpy 1.x's C API.
* :func:`write_model` - a Python-backend model (``model.py`` + ``config.pbtxt``)
  that runs an ``.onnx`` file with ONNX Runtime: the same protocol and tensors
  as Triton's ONNX Runtime backend. ``mode="wrong_shape"`` replies one column
  short (a broken server); ``delay_ms`` holds each reply back (frames stay in flight).
* :class:`TritonServer` - ``tritonserver`` on 127.0.0.1 with free ports, waited
  for until ready; :meth:`~TritonServer.kill` (SIGKILL) and :meth:`~TritonServer.stop`.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import shutil
import signal
import subprocess
import sys
import time
import urllib.request
from collections.abc import Sequence
from pathlib import Path

from helpers.zenoh_loopback import free_port

#: What the server venv holds; a new key builds a new venv beside the old one.
PYTRITON = "nvidia-pytriton==0.7.0"
VENV_KEY = "pytriton-0.7.0-np1-ort-1"
VENV_ENV = "VPP_TEST_TRITON_VENV"

#: The server-side model.py: it runs in the server's own venv (numpy<2, onnxruntime, Triton's
#: triton_python_backend_utils), never in the tests' interpreter, so it is kept as a template file.
_MODEL_PY = Path(__file__).with_name("triton_model.py.in")


def venv_dir() -> Path:
    """Where the server venv lives (it may not exist yet)."""
    env = os.environ.get(VENV_ENV, "").strip()
    if env:
        return Path(env).expanduser()
    return Path.home() / ".cache" / "vpp-service-tests" / f"triton-venv-{VENV_KEY}"


def _site(venv: Path) -> Path:
    return venv / "lib" / f"python{sys.version_info.major}.{sys.version_info.minor}" / "site-packages"


def server_venv() -> Path:
    """The server venv, built on first use (about 70 s and 330 MB on the dev machine; a lock serialises builders).

    Raises
    ------
    subprocess.CalledProcessError
        pip could not install the server's packages.
    """
    venv = venv_dir()
    done = venv / ".complete"
    if done.is_file():
        return venv
    venv.parent.mkdir(parents=True, exist_ok=True)
    with open(venv.parent / f".{venv.name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if done.is_file():
            return venv
        shutil.rmtree(venv, ignore_errors=True)
        # the system Python of this interpreter (the stub links its libpython): not the project venv's packages
        base = Path(sys.base_prefix) / "bin" / f"python{sys.version_info.major}.{sys.version_info.minor}"
        subprocess.run([str(base), "-m", "venv", str(venv)], check=True)
        pip = [str(venv / "bin" / "python"), "-m", "pip", "install", "-q", "--disable-pip-version-check"]
        subprocess.run([*pip, "--no-deps", PYTRITON], check=True)
        subprocess.run([*pip, "numpy<2", "onnxruntime"], check=True)
        done.write_text(VENV_KEY + "\n")
    return venv


def backend_dir(venv: Path, where: Path) -> Path:
    """A backend folder for ``--backend-directory``: ``python/`` with the wheel's backend and a link to its stub."""
    tri = _site(venv) / "pytriton" / "tritonserver"
    py = where / "python"
    py.mkdir(parents=True, exist_ok=True)
    for name in ("libtriton_python.so", "triton_python_backend_utils.py"):
        target = py / name
        if not target.exists():
            target.symlink_to(tri / "backends" / "python" / name)
    stub = py / "triton_python_backend_stub"
    if not stub.exists():  # a link: the stub finds its libraries relative to its real path
        ver = f"{sys.version_info.major}.{sys.version_info.minor}"
        stub.symlink_to(tri / "python_backend_stubs" / ver / "triton_python_backend_stub")
    return where


def _dims(shape: Sequence[int | None]) -> str:
    return "[ " + ", ".join(str(-1 if d is None else d) for d in shape) + " ]"


def write_model(
    repo: Path,
    name: str,
    onnx_path: Path,
    inputs: dict[str, Sequence[int | None]],
    outputs: dict[str, Sequence[int | None]],
    *,
    mode: str = "",
    delay_ms: float = 0.0,
    threads: int = 1,
    dtype: str = "TYPE_FP32",
) -> Path:
    """Write ``repo/name`` (version 1): a Python-backend model running ``onnx_path`` with ONNX Runtime.

    ``inputs`` / ``outputs``: tensor name -> shape (None = dynamic), as ``config.pbtxt`` declares them;
    ``dtype`` is the declared datatype of every tensor (the model computes float32 whatever it says).
    """
    folder = repo / name
    (folder / "1").mkdir(parents=True, exist_ok=True)
    (folder / "1" / "model.py").write_text(_MODEL_PY.read_text())
    tensors = lambda spec: ",\n".join(  # noqa: E731
        f'  {{ name: "{n}" data_type: {dtype} dims: {_dims(s)} }}' for n, s in spec.items()
    )
    params = {"onnx": str(onnx_path), "threads": str(threads), "mode": mode, "delay_ms": str(delay_ms)}
    param_text = "\n".join(
        f'parameters: {{ key: "{k}" value: {{ string_value: {json.dumps(v)} }} }}' for k, v in params.items()
    )
    (folder / "config.pbtxt").write_text(
        f'name: "{name}"\nbackend: "python"\nmax_batch_size: 0\n'
        f"input [\n{tensors(inputs)}\n]\noutput [\n{tensors(outputs)}\n]\n"
        f"instance_group [ {{ kind: KIND_CPU count: 1 }} ]\n{param_text}\n"
    )
    return folder


class TritonServer:
    """One ``tritonserver`` process on 127.0.0.1 serving ``repo`` (started by :meth:`start`).

    Attributes
    ----------
    url : str
        ``127.0.0.1:<grpc port>``, what the ``triton`` engine's ``url`` takes.
    http_port, metrics_port : int
    log : Path
        The server's stdout and stderr.
    """

    def __init__(self, venv: Path, repo: Path, work: Path) -> None:
        self.venv, self.repo, self.work = venv, repo, work
        work.mkdir(parents=True, exist_ok=True)
        self.backends = backend_dir(venv, work / "backends")
        self.grpc_port, self.http_port, self.metrics_port = free_port(), free_port(), free_port()
        self.url = f"127.0.0.1:{self.grpc_port}"
        self.log = work / "tritonserver.log"
        self.proc: subprocess.Popen[bytes] | None = None

    def start(self, timeout: float = 120.0) -> TritonServer:
        """Start the server and wait until it is ready (all models loaded).

        Raises
        ------
        RuntimeError
            It exited or was not ready within ``timeout``; the message ends with its log.
        """
        exe = _site(self.venv) / "pytriton" / "tritonserver" / "bin" / "tritonserver"
        env = dict(os.environ)
        # the stub takes its packages from the first python3 on PATH and links the system libpython
        env["PATH"] = f"{self.venv / 'bin'}:{env.get('PATH', '')}"
        env["LD_LIBRARY_PATH"] = f"{Path(sys.base_prefix) / 'lib'}:{env.get('LD_LIBRARY_PATH', '')}"
        env.pop("PYTHONPATH", None)
        cmd = [
            str(exe),
            f"--model-repository={self.repo}",
            f"--backend-directory={self.backends}",
            "--grpc-address=127.0.0.1",
            f"--grpc-port={self.grpc_port}",
            "--http-address=127.0.0.1",
            f"--http-port={self.http_port}",
            "--metrics-address=127.0.0.1",
            f"--metrics-port={self.metrics_port}",
            "--log-verbose=0",
        ]
        with open(self.log, "wb") as out:
            self.proc = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, env=env, start_new_session=True)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise RuntimeError(f"tritonserver exited with {self.proc.returncode}:\n{self.log_text()}")
            if self.ready():
                return self
            time.sleep(0.2)
        self.stop()
        raise RuntimeError(f"tritonserver not ready within {timeout:g} s:\n{self.log_text()}")

    def ready(self) -> bool:
        """True when the server answers ``/v2/health/ready`` with 200."""
        try:
            with urllib.request.urlopen(f"http://127.0.0.1:{self.http_port}/v2/health/ready", timeout=1) as r:
                return bool(r.status == 200)
        except OSError:
            return False

    def metrics(self) -> str:
        """The server's Prometheus metrics text."""
        with urllib.request.urlopen(f"http://127.0.0.1:{self.metrics_port}/metrics", timeout=5) as r:
            return str(r.read().decode())

    def log_text(self, tail: int = 4000) -> str:
        """The end of the server's log."""
        try:
            return self.log.read_text(errors="replace")[-tail:]
        except OSError:
            return ""

    def kill(self) -> None:
        """SIGKILL the server (and its stubs: the whole process group) and wait for it."""
        if self.proc is not None and self.proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait(10)

    def stop(self, timeout: float = 15.0) -> None:
        """Stop the server (SIGTERM, then SIGKILL after ``timeout``)."""
        if self.proc is None or self.proc.poll() is not None:
            return
        with contextlib.suppress(ProcessLookupError):
            os.killpg(self.proc.pid, signal.SIGTERM)
        try:
            self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.kill()


__all__ = ["VENV_KEY", "TritonServer", "backend_dir", "server_venv", "venv_dir", "write_model"]
