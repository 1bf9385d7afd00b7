"""The README's two commands: the first installs and runs the main job, CI runs exactly the second."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _bash_blocks() -> list[str]:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    return [b.strip() for b in re.findall(r"```bash\n(.*?)```", text, flags=re.DOTALL)]


def test_ci_runs_the_readme_test_command_exactly():
    first, second = _bash_blocks()[:2]
    assert first.startswith("pip install -e . && vpp-service run")  # editable: the build stays for the second
    assert second == 'pip install -e ".[test]" && python -m pytest -q'
    assert second in (ROOT / ".ci" / "run").read_text(encoding="utf-8").splitlines()


def test_readme_says_a_c_compiler_with_openmp_is_needed():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    head = text[: text.index("```bash")]
    assert "C compiler with OpenMP" in head


def test_readme_says_what_the_shared_data_folder_is_without_pointing_into_it():
    """A fresh clone has no ../shared: the README says what is in it and where it comes from, itself."""
    text = " ".join((ROOT / "README.md").read_text(encoding="utf-8").split())
    para = text[text.index("**Test data.**") :]
    para = para[: para.index("## ")]
    assert not re.search(r"its `?README", para)  # no pointer to a README the reader does not have
    assert "a fresh clone does not have" in para
    for site in ("vision.middlebury.edu/stereo", "cvlibs.net/datasets/kitti", "eth3d.net"):
        assert site in para
    shared = ROOT.parent / "shared" / "data"
    if shared.is_dir():  # where the folder is here: every sub-folder the README names exists
        for name in re.findall(r"`([a-z0-9_]+)/`", para):
            assert (shared / name).is_dir(), name
