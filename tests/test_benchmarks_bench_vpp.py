"""benchmarks/bench_vpp.py: the performance table it renders, the docs block it replaces, where it writes."""

from __future__ import annotations

import importlib.util
import json
import re
import sys
from pathlib import Path
from types import ModuleType

import pytest

from vpp_service.threads import resolve_threads

REPO = Path(__file__).resolve().parents[1]
BENCHMARKS = REPO / "benchmarks"

HEAD = (
    "| image | points | copy | default (vi), 1 thread | default (vi), 4 threads | default (vi) / copy, 4 threads "
    "| histogram (vii), 1 thread | histogram (vii), 4 threads |\n"
    "|---|---|---:|---:|---:|---:|---:|---:|"
)


@pytest.fixture
def bench(monkeypatch: pytest.MonkeyPatch) -> ModuleType:
    """benchmarks/bench_vpp.py loaded from its file (its folder on sys.path, as when run as a script)."""
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    spec = importlib.util.spec_from_file_location("bench_vpp", BENCHMARKS / "bench_vpp.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, "bench_vpp", module)
    spec.loader.exec_module(module)
    return module


def _row(
    size: str,
    H: int,
    W: int,
    density: float,
    pattern: str,
    threads: int,
    ms: float,
    ratio: float = 1.0,
    points: int | None = None,
) -> dict[str, object]:
    row: dict[str, object] = dict(
        size=size, H=H, W=W, density=density, pattern=pattern, threads=threads, ms=ms, min_ms=ms
    )
    row.update(ratio=ratio, min_ratio=ratio)
    if points is not None:
        row.update(paired_ratio=ratio, points=points)
    return row


def synthetic_doc(**extra: object) -> dict[str, object]:
    """Two densities of one 3 x 2 image, 1 and 4 threads; values chosen for each number format."""
    rows: list[dict[str, object]] = []
    for density, scale in ((0.05, 1.0), (0.01, 0.5)):
        rows += [
            _row("tiny", 2, 3, density, "copy", 1, 0.061 * scale),
            _row("tiny", 2, 3, density, "random", 1, 12.34 * scale, 202.3, round(1234 * scale)),
            _row("tiny", 2, 3, density, "random", 4, 150.4 * scale, 7.26 / scale, round(1234 * scale)),
            _row("tiny", 2, 3, density, "histogram", 1, 5.5 * scale, 90.2, round(1234 * scale)),
            _row("tiny", 2, 3, density, "histogram", 4, 42.0 * scale, 688.5, round(1234 * scale)),
        ]
    return {"cpu_count": 8, "memory": "reused", "results": rows, **extra}


def test_markdown_table_renders_every_column(bench):
    assert bench.markdown_table(synthetic_doc()) == (
        "Median ms of each call, including the output allocation; 8 CPUs; freed memory reused.\n\n"
        + HEAD
        + "\n| 3 x 2 | 5 % (1,234) | 0.06 | 12.3 | 150 | 7.3 | 5.50 | 42.0 |"
        + "\n| 3 x 2 | 1 % (617) | 0.03 | 6.17 | 75.2 | 14.5 | 2.75 | 21.0 |"
    )


@pytest.mark.parametrize(
    ("extra", "machine"),
    [
        ({"cpu": "Example CPU 9000", "avx2": True}, "Example CPU 9000, AVX2 build"),
        ({"cpu": None, "avx2": False}, "8 CPUs, portable build"),
        ({"avx2": True}, "8 CPUs, AVX2 build"),
        ({"cpu": "Example CPU 9000"}, "Example CPU 9000"),
    ],
)
def test_markdown_table_caption_names_the_machine_and_build(bench, extra, machine):
    caption = bench.markdown_table(synthetic_doc(**extra)).split("\n", 1)[0]
    assert caption == f"Median ms of each call, including the output allocation; {machine}; freed memory reused."


def test_replace_block_replaces_only_the_marked_block(bench):
    text = f"# Page\n\nbefore\n{bench.BEGIN}\nold table\n| a |\n{bench.END}\nafter\n"
    new = bench.replace_block(text, "new table")
    assert new == f"# Page\n\nbefore\n{bench.BEGIN}\nnew table\n{bench.END}\nafter\n"
    assert bench.replace_block(new, "new table") == new  # regenerating the same table changes nothing
    assert bench.replace_block(text, r"\1 \g<0>") == text.replace("old table\n| a |", r"\1 \g<0>")  # taken literally


@pytest.mark.parametrize("blocks", [0, 2])
def test_replace_block_needs_exactly_one_block(bench, blocks):
    text = "intro\n" + f"{bench.BEGIN}\nx\n{bench.END}\n" * blocks
    with pytest.raises(ValueError, match=rf"page\.md: expected one .* block, found {blocks}"):
        bench.replace_block(text, "table", source="page.md")


def test_update_doc_writes_the_table_between_the_markers(bench, tmp_path):
    page = tmp_path / "algorithm.md"
    page.write_text(f"## Performance\n\n{bench.BEGIN}\nstale\n{bench.END}\n\nRegenerate it.\n")
    doc = synthetic_doc(cpu="Example CPU 9000", avx2=False)
    bench.update_doc(page, doc)
    assert page.read_text() == (
        f"## Performance\n\n{bench.BEGIN}\n{bench.markdown_table(doc)}\n{bench.END}\n\nRegenerate it.\n"
    )


def test_update_doc_without_markers_leaves_the_page_alone(bench, tmp_path):
    page = tmp_path / "algorithm.md"
    page.write_text("## Performance\n\nno table here\n")
    with pytest.raises(ValueError, match="found 0"):
        bench.update_doc(page, synthetic_doc())
    assert page.read_text() == "## Performance\n\nno table here\n"


def test_the_committed_table_is_the_one_the_committed_json_renders(bench):
    doc = json.loads((REPO / "benchmarks" / "results" / "bench_vpp.json").read_text())
    page = (REPO / "docs" / "algorithm.md").read_text()
    assert bench.replace_block(page, bench.markdown_table(doc)) == page


def test_cpu_model_reads_the_model_name(bench, tmp_path):
    info = tmp_path / "cpuinfo"
    info.write_text("processor\t: 0\nvendor_id\t: Example\nmodel name\t: Example CPU 9000 @ 3.0GHz\nflags\t: avx2\n")
    assert bench.cpu_model(info) == "Example CPU 9000 @ 3.0GHz"
    info.write_text("processor\t: 0\n")
    assert bench.cpu_model(info) is None
    assert bench.cpu_model(tmp_path / "missing") is None


def test_update_docs_refuses_a_partial_run(bench, capsys):
    for args in (["--update-docs", "--quick"], ["--update-docs", "--reps", "3"]):
        with pytest.raises(SystemExit) as exit_info:
            bench.main(args)
        assert exit_info.value.code == 2
        assert "--update-docs needs the full run" in capsys.readouterr().err


@pytest.fixture
def tiny_bench(bench, tmp_path, monkeypatch):
    """bench_vpp on tiny scenes, with the committed JSON and the page redirected to tmp_path."""
    monkeypatch.setattr(bench, "SIZES", {"kitti": (12, 40), "midd_half": (10, 30), "midd_full": (8, 24)})
    monkeypatch.setattr(bench, "COMMITTED_JSON", tmp_path / "results" / "bench_vpp.json")
    monkeypatch.setattr(bench, "DOC", tmp_path / "algorithm.md")
    monkeypatch.setenv("OMP_WAIT_POLICY", "PASSIVE")  # configure_openmp keeps it; the test process is unchanged
    bench.DOC.write_text(f"before\n{bench.BEGIN}\nstale\n{bench.END}\nafter\n")
    return bench


def test_a_run_writes_only_its_out_file(tiny_bench, tmp_path):
    from vpp_service.vpp import backend

    out = tmp_path / "local" / "run.json"
    assert tiny_bench.main(["--quick", "--reps", "1", "--fresh-memory", "--out", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert doc["avx2"] is backend.AVX2 and doc["memory"] == "fresh" and doc["reps"] == 1
    assert "cpu" in doc and "cpu_count" in doc
    assert [(r["size"], r["pattern"]) for r in doc["results"] if r["threads"] == 1] == [
        (size, pattern) for size in ("kitti", "midd_half") for pattern in ("copy", "random", "histogram")
    ]
    assert not tiny_bench.COMMITTED_JSON.exists()
    assert "stale" in tiny_bench.DOC.read_text()


def test_update_docs_writes_the_committed_json_and_the_table(tiny_bench, tmp_path):
    out = tmp_path / "local" / "run.json"
    assert tiny_bench.main(["--update-docs", "--fresh-memory", "--out", str(out)]) == 0
    doc = json.loads(tiny_bench.COMMITTED_JSON.read_text())
    assert doc == json.loads(out.read_text())
    per_scene = 1 + 2 * len({1, resolve_threads(None)})  # the copy, then 2 patterns x thread counts
    assert len(doc["results"]) == 3 * 2 * per_scene
    page = tiny_bench.DOC.read_text()
    assert page == f"before\n{tiny_bench.BEGIN}\n{tiny_bench.markdown_table(doc)}\n{tiny_bench.END}\nafter\n"
    assert re.search(r"^\| 40 x 12 \| 1 % \(", page, flags=re.MULTILINE)
