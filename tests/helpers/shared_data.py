"""The external data the tests read in place: ``<repo>/../shared/data`` and ``/models`` (not in the repository).

``data`` holds real benchmark scenes (Middlebury 2001-2006, KITTI 2012 frame 000070, ETH3D
playground_1l), ``models`` the PSMNet ONNX model; each has a README.md. A fresh clone does not
have them: every test that reads them asks :func:`need_shared` for its folder or file, which
**skips** the test with a reason naming the missing path.
CI sets ``VPP_REQUIRE_SHARED_DATA=1`` (``.ci/run``): there a missing folder **fails** the test
instead, so coverage of the real scenes cannot vanish silently.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

#: The repository root (this file is ``tests/helpers/shared_data.py``).
REPO_ROOT = Path(__file__).resolve().parents[2]
#: The shared evaluation data: beside the repository root.
SHARED_DATA = REPO_ROOT.parent / "shared" / "data"
#: Set (to 1) where the shared data must be present: a missing folder fails instead of skipping.
REQUIRE_ENV = "VPP_REQUIRE_SHARED_DATA"


def need_shared(relative: str, under: str = "data") -> Path:
    """The path ``<repo>/../shared/<under>/<relative>``; skip (or fail under ``$VPP_REQUIRE_SHARED_DATA``) when absent.

    Parameters
    ----------
    relative : str
        A folder or file inside it, e.g. ``"kitti2012_training/000070"``.
    under : {"data", "models"}
        The shared benchmark scenes, or the shared models (``psmnet_kitti2015.onnx``).
    """
    path = SHARED_DATA.parent / under / relative
    if path.exists():
        return path
    reason = (
        f"shared evaluation data missing: {path} (the real benchmark scenes this test reads are expected in "
        f"<repo>/../shared/data; see README.md, 'Test data')"
    )
    if os.environ.get(REQUIRE_ENV, "") not in ("", "0"):
        pytest.fail(f"{reason}; ${REQUIRE_ENV} is set, so it must be there", pytrace=False)
    pytest.skip(reason)
