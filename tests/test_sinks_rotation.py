"""Numbered rotation of an output file (the Rerun sink's size cap, a resumed service's summary.json)."""

from __future__ import annotations

import pytest

from vpp_service.sinks.rotation import rotate, rotated_paths


def test_rotated_paths_number_before_the_suffix(tmp_path):
    assert [p.name for p in rotated_paths(tmp_path / "summary.json", 3)] == [
        "summary.json",
        "summary.1.json",
        "summary.2.json",
    ]
    assert [p.name for p in rotated_paths(tmp_path / "bag", 2)] == ["bag", "bag.1"]


def test_rotate_shifts_and_keeps_at_most_max_files(tmp_path):
    path = tmp_path / "summary.json"
    for run in range(5):
        path.write_text(f"run {run}")
        kept = rotate(path, 3)
        assert not path.exists()
        assert kept[0].read_text() == f"run {run}"  # the newest rotated file is the run just moved
    names = {p.name: p.read_text() for p in tmp_path.iterdir()}
    assert names == {"summary.1.json": "run 4", "summary.2.json": "run 3"}  # 3 kept with the next run's own


def test_rotate_keeps_gaps_and_moves_only_what_exists(tmp_path):
    path = tmp_path / "vpp.rrd"
    path.write_bytes(b"new")
    (tmp_path / "vpp.2.rrd").write_bytes(b"old")
    assert [p.name for p in rotate(path, 4)] == ["vpp.1.rrd", "vpp.3.rrd"]
    assert (tmp_path / "vpp.1.rrd").read_bytes() == b"new" and (tmp_path / "vpp.3.rrd").read_bytes() == b"old"


def test_rotate_with_one_file_deletes_it(tmp_path):
    path = tmp_path / "vpp.rrd"
    path.write_bytes(b"x")
    assert rotate(path, 1) == [] and not path.exists()


def test_rotate_refuses_less_than_one_file(tmp_path):
    with pytest.raises(ValueError, match="max_files"):
        rotate(tmp_path / "x.json", 0)
