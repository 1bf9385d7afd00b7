"""The installed ``vpp-service`` console script, as the end-to-end tests start it."""

from __future__ import annotations

import shutil
import sys
from pathlib import Path


def vpp_service_command() -> list[str]:
    """Argument list that starts the installed ``vpp-service`` command.

    The script is looked up beside the running interpreter first (a virtual
    environment's ``bin/``), then on ``PATH``.

    Raises
    ------
    FileNotFoundError
        When the package is not installed (``pip install -e ".[test]"`` puts it there).
    """
    here = Path(sys.executable).with_name("vpp-service")
    if here.is_file():
        return [str(here)]
    found = shutil.which("vpp-service")
    if found is None:
        raise FileNotFoundError("the vpp-service console script is not installed: run pip install -e '.[test]'")
    return [found]


def vpp_service_module_command() -> list[str]:
    """Argument list that runs ``vpp-service`` from the imported checkout: ``python -m vpp_service``.

    Run it with the repository root as the working directory (``-m`` puts the
    working directory first on ``sys.path``), so a worktree's own code runs even
    where the editable install points at another checkout.
    """
    return [sys.executable, "-m", "vpp_service"]
