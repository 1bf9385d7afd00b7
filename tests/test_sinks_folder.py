"""The folder sinks' files: names from validated parts only, paths inside the folder, the umask's mode."""

from __future__ import annotations

import stat
from pathlib import Path

import pytest

from vpp_service.sinks.folder import check_name, path_inside, write_atomic

HOSTILE_NAMES = [
    "../../x/relative",
    "..",
    ".",
    "/abs/path",
    "/tmp/x",
    ".hidden",
    "a\x00b",
    "a/b",
    "a\\b",
    "",
    "x" * 201,
    "rig\n0",
]


@pytest.mark.parametrize("name", HOSTILE_NAMES)
def test_check_name_refuses_hostile_names(name):
    with pytest.raises(ValueError, match="is not a safe file name"):
        check_name(name, "frame.rig")


@pytest.mark.parametrize("name", ["rig0", "rig-A_1", "r1.left", "0", "x" * 200])
def test_check_name_accepts_plain_names(name):
    assert check_name(name, "frame.rig") == name


def test_check_name_refuses_non_strings():
    with pytest.raises(ValueError, match=r"frame\.rig: 3 is not a safe file name"):
        check_name(3, "frame.rig")


@pytest.mark.parametrize("name", HOSTILE_NAMES)
def test_path_inside_refuses_hostile_names(tmp_path, name):
    with pytest.raises(ValueError, match="not a safe file name"):
        path_inside(tmp_path, name)


def test_path_inside_refuses_a_symlink_that_leaves_the_folder(tmp_path):
    folder = tmp_path / "out"
    folder.mkdir()
    (tmp_path / "secret").write_text("x")
    (folder / "link.png").symlink_to(tmp_path / "secret")
    with pytest.raises(ValueError, match="outside"):
        path_inside(folder, "link.png")


def test_path_inside_follows_a_symlinked_folder(tmp_path):
    real = tmp_path / "real"
    real.mkdir()
    (tmp_path / "alias").symlink_to(real)
    assert path_inside(tmp_path / "alias", "rig0_000001.png") == tmp_path / "alias" / "rig0_000001.png"


@pytest.mark.parametrize("how", ["bytes", "callable"])
@pytest.mark.parametrize("overwrite", [False, True])
def test_write_atomic_honours_the_umask(tmp_path, umask, how, overwrite):
    """The renamed file has the mode a plain open() gives, 0o666 less the umask (not mkstemp's 0o600)."""
    path = tmp_path / "rig0_000001_disparity.png"
    data = b"\x89PNG"
    write_atomic(path, data if how == "bytes" else (lambda p: Path(p).write_bytes(data)), overwrite=overwrite)
    assert path.read_bytes() == data
    assert stat.S_IMODE(path.stat().st_mode) == 0o666 & ~umask
    assert [p.name for p in tmp_path.iterdir()] == [path.name]  # no temporary file left


def test_write_atomic_replacing_a_private_file_gives_the_umask_mode(tmp_path, umask):
    """An existing 0o600 file replaced with overwrite: the new file's mode comes from the umask, not the old file."""
    path = tmp_path / "summary.json"
    path.write_text("{}")
    path.chmod(0o600)
    write_atomic(path, b"{}\n", overwrite=True)
    assert stat.S_IMODE(path.stat().st_mode) == 0o666 & ~umask
