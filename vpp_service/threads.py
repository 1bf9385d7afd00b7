"""OpenMP threads of the compiled kernels: how many, and how they wait.

One policy for every kernel (VPP and the matchers):

* :func:`resolve_threads` - an explicit count is used as given; ``None`` means
  :func:`default_threads`: ``OMP_NUM_THREADS`` when set (its first entry),
  else the CPUs this process may run on (its affinity mask). Not
  ``os.cpu_count()``: on a shared machine, in a container with a CPU set or
  under ``taskset``/systemd ``CPUAffinity``, the host's CPU count would start
  more threads than the process has cores, and oversubscribed OpenMP regions
  that synchronise per row get slower, not faster. The operator's
  ``OMP_NUM_THREADS`` is the one knob that caps every kernel at once.
* :func:`configure_openmp` - the wait policy of the OpenMP workers between
  parallel regions. It is the **caller's** choice, made where threads are
  started: the ``vpp-service`` command calls it first thing, before any kernel
  module is imported; importing :mod:`vpp_service` changes nothing in the
  environment.
"""

from __future__ import annotations

import operator
import os
from collections.abc import MutableMapping
from typing import SupportsIndex


def default_threads() -> int:
    """Threads a kernel uses when not told: ``OMP_NUM_THREADS`` if set (> 0), else the usable CPUs.

    ``OMP_NUM_THREADS`` may be a list (``"4,2"``, nested levels): its first
    entry counts. Without it, the size of this process's CPU affinity mask
    (where the platform has one), else ``os.cpu_count()``; at least 1.
    """
    env = os.environ.get("OMP_NUM_THREADS", "").split(",")[0].strip()
    if env.isdigit() and int(env) > 0:
        return int(env)
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - no affinity API (not Linux)
        return max(1, os.cpu_count() or 1)


def resolve_threads(n: SupportsIndex | None, name: str = "threads") -> int:
    """The thread count for a kernel call: ``n`` itself (>= 1), or :func:`default_threads` for None.

    Parameters
    ----------
    n : int, numpy integer or None
        Requested threads; None = the default policy.
    name : str
        Argument name used in error messages.

    Returns
    -------
    int
        Threads, >= 1.

    Raises
    ------
    TypeError
        ``n`` is a bool or not an integer.
    ValueError
        ``n`` < 1.
    """
    if n is None:
        return default_threads()
    if isinstance(n, bool):
        raise TypeError(f"{name} must be an integer or None, got {n!r}")
    try:
        count = operator.index(n)  # int and numpy integers; not float, str or numpy bool
    except TypeError:
        raise TypeError(f"{name} must be an integer or None, got {n!r}") from None
    if count < 1:
        raise ValueError(f"{name} must be >= 1 (or None for the default), got {count}")
    return count


def configure_openmp(environ: MutableMapping[str, str] | None = None) -> bool:
    """Let OpenMP workers sleep right after each parallel region, unless the user chose otherwise.

    Sets ``OMP_WAIT_POLICY=PASSIVE`` when neither ``OMP_WAIT_POLICY`` nor
    ``GOMP_SPINCOUNT`` is set. A streaming service calls the kernels once per
    frame with idle gaps in between: with libgomp's default (spin a while,
    then sleep) the workers burn CPU that the matcher and the transport need
    on a small host, and the first region after a gap starts later than with
    passive workers (``docs/deployment.md``, "Process tuning", also for the
    spinning low-latency alternative, ``GOMP_SPINCOUNT``).

    libgomp reads the variable once, when it is loaded: call this before the
    first import of a compiled kernel (``vpp_service.vpp``,
    ``vpp_service.matchers``) or of any other library that loads OpenMP. The
    ``vpp-service`` command does so at the top of its ``main``; a program that
    embeds the service makes the same call (or sets the variable itself).

    Parameters
    ----------
    environ : mutable mapping or None
        Environment to update (default ``os.environ``).

    Returns
    -------
    bool
        True when the policy was set here, False when the user's setting was kept.
    """
    env = os.environ if environ is None else environ
    if "OMP_WAIT_POLICY" in env or "GOMP_SPINCOUNT" in env:
        return False
    env["OMP_WAIT_POLICY"] = "PASSIVE"
    return True


__all__ = ["configure_openmp", "default_threads", "resolve_threads"]
