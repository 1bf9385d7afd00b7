"""Benchmarks and the results script write outside the committed results unless asked to overwrite them."""

from __future__ import annotations

import argparse
import importlib.util
import sys
from pathlib import Path
from types import ModuleType

ROOT = Path(__file__).resolve().parents[1]


def _load(path: Path, name: str) -> ModuleType:
    spec = importlib.util.spec_from_file_location(name, path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


def test_benchmark_reports_default_to_a_scratch_folder(tmp_path):
    harness = _load(ROOT / "benchmarks" / "_harness.py", "_harness_under_test")
    ap = argparse.ArgumentParser()
    harness.add_output_args(ap, "bench_x")
    default = harness.output_path(ap.parse_args([]), "bench_x")
    assert default == ROOT / "out" / "benchmarks" / "bench_x.json"
    committed = harness.output_path(ap.parse_args(["--update-committed"]), "bench_x")
    assert committed == ROOT / "benchmarks" / "results" / "bench_x.json"
    assert harness.output_path(ap.parse_args(["--json", str(tmp_path / "a.json")]), "bench_x") == tmp_path / "a.json"


def test_out_is_ignored_by_git():
    assert "out/" in (ROOT / ".gitignore").read_text().split()


def test_make_results_writes_to_a_scratch_folder_by_default(tmp_path, capsys):
    """--render-only from a results.json: without --update-docs nothing under docs/ is touched."""
    script = _load(ROOT / "scripts" / "make_results.py", "make_results_under_test")
    assert script.DEFAULT_OUT == ROOT / "out" / "results"
    docs = ROOT / "docs" / "results.md"
    before = docs.stat().st_mtime_ns
    out = tmp_path / "o"
    (out / "results").mkdir(parents=True)
    (out / "results" / "results.json").write_bytes((ROOT / "docs" / "results" / "results.json").read_bytes())
    assert script.main(["--render-only", "--out", str(out)]) == 0
    assert (out / "results.md").is_file() and docs.stat().st_mtime_ns == before
