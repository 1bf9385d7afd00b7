"""One thread-count policy for every kernel, and the OpenMP wait policy set by the command, not by an import."""

from __future__ import annotations

import importlib
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from vpp_service.threads import configure_openmp, default_threads, resolve_threads

REPO = Path(__file__).resolve().parents[1]


def test_resolve_threads_explicit_and_default(monkeypatch):
    assert resolve_threads(3) == 3 and resolve_threads(np.int64(2)) == 2
    assert type(resolve_threads(np.int64(2))) is int
    monkeypatch.setenv("OMP_NUM_THREADS", "3")
    assert resolve_threads(None) == default_threads() == 3


@pytest.mark.parametrize(
    ("value", "exc"), [(True, TypeError), (1.0, TypeError), ("2", TypeError), (0, ValueError), (-1, ValueError)]
)
def test_resolve_threads_rejects(value, exc):
    with pytest.raises(exc, match="threads"):
        resolve_threads(value, "threads")


@pytest.mark.parametrize(("env", "expected"), [("4,2", 4), (" 5 ", 5), ("0", None), ("many", None), (None, None)])
def test_default_threads_honours_omp_num_threads_else_affinity(monkeypatch, env, expected):
    if env is None:
        monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    else:
        monkeypatch.setenv("OMP_NUM_THREADS", env)
    usable = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    assert default_threads() == (expected if expected is not None else usable)


def test_vpp_and_matchers_share_the_policy(monkeypatch):
    from vpp_service.matchers import census_sgm
    from vpp_service.vpp import VPPConfig, detect_occlusions, project

    # the modules (the package's ``project`` attribute is the function)
    project_module = importlib.import_module("vpp_service.vpp.project")
    occlusion = importlib.import_module("vpp_service.vpp.occlusion")

    img = np.zeros((8, 12), np.uint8)
    disp = np.zeros((8, 12), np.float32)
    with pytest.raises(ValueError, match="threads"):
        project(img, img, disp, VPPConfig(), threads=0)
    with pytest.raises(ValueError, match="threads"):
        detect_occlusions(disp, threads=0)
    with pytest.raises(ValueError, match="threads"):
        census_sgm.census_transform(img, 0)  # 0 is not a count (None is the default)
    seen: list[object] = []

    def record(n, name="threads"):
        seen.append(n)
        return 1

    for module in (census_sgm, project_module, occlusion):
        monkeypatch.setattr(module, "resolve_threads", record)
    census_sgm.census_transform(img)
    census_sgm.census_transform(img, 2)
    project(img, img, disp, VPPConfig())
    project(img, img, disp, VPPConfig(), threads=2)
    detect_occlusions(disp)
    assert seen == [None, 2, None, 2, None]


@pytest.mark.parametrize(
    ("env", "expected", "changed"),
    [
        ({}, {"OMP_WAIT_POLICY": "PASSIVE"}, True),
        ({"OMP_WAIT_POLICY": "ACTIVE"}, {"OMP_WAIT_POLICY": "ACTIVE"}, False),
        ({"GOMP_SPINCOUNT": "1000"}, {"GOMP_SPINCOUNT": "1000"}, False),
    ],
)
def test_configure_openmp_keeps_the_users_choice(env, expected, changed):
    env = dict(env)
    assert configure_openmp(env) is changed
    assert env == expected


def _clean_env(**extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("OMP_WAIT_POLICY", "GOMP_SPINCOUNT")}
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    env.update(extra)
    return env


def _python(code: str, **extra: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", code],
        cwd=REPO,
        env=_clean_env(**extra),
        capture_output=True,
        text=True,
        timeout=120,
        check=False,  # the callers assert on the exit code with the output in the message
    )


def test_importing_the_package_leaves_the_environment_alone():
    # cv2's own loader edits LD_LIBRARY_PATH when first imported: import it before the snapshot
    code = (
        "import os, cv2; before = dict(os.environ)\n"
        "import vpp_service, vpp_service.vpp, vpp_service.matchers, vpp_service.fusion, vpp_service.cli\n"
        "assert dict(os.environ) == before, set(os.environ.items()) ^ set(before.items())\n"
        "print('unchanged')"
    )
    proc = _python(code)
    assert proc.returncode == 0 and "unchanged" in proc.stdout, proc.stderr


def test_the_command_sets_the_policy_before_openmp_loads():
    # the command's module loads no OpenMP runtime, so main() can still set the policy
    proc = _python("import vpp_service.cli\nprint(any('gomp' in line for line in open('/proc/self/maps')))")
    assert proc.returncode == 0 and proc.stdout.strip() == "False", proc.stderr
    proc = _python("import os; from vpp_service.cli import main; main([]); print(os.environ['OMP_WAIT_POLICY'])")
    assert proc.stdout.strip().splitlines()[-1] == "PASSIVE", proc.stderr


def _libgomp_spincount(args: list[str], **extra: str) -> str:
    """GOMP_SPINCOUNT as libgomp itself read it at load (OMP_DISPLAY_ENV=verbose), in a fresh process."""
    proc = subprocess.run(
        [sys.executable, *args],
        cwd=REPO,
        env=_clean_env(OMP_DISPLAY_ENV="verbose", **extra),
        capture_output=True,
        text=True,
        timeout=120,
        check=False,  # the exit code is asserted below, with stderr in the message
    )
    assert proc.returncode == 0, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if "GOMP_SPINCOUNT" in ln]
    if not lines:
        pytest.skip("the OpenMP runtime is not libgomp (no GOMP_SPINCOUNT display)")
    return lines[0].split("=", 1)[1].strip().strip("'")


def test_libgomp_sees_the_passive_policy_only_through_the_command():
    assert _libgomp_spincount(["-m", "vpp_service", "run", "--check"]) == "0"  # PASSIVE: never spin
    assert _libgomp_spincount(["-c", "import vpp_service.vpp"]) != "0"  # plain import: libgomp's default
    assert _libgomp_spincount(["-m", "vpp_service", "run", "--check"], GOMP_SPINCOUNT="1234") == "1234"
