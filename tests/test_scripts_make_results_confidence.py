"""scripts/make_results.py --confidence: its section of the page from the stored document, between markers."""

from __future__ import annotations

import json
from types import ModuleType

import pytest

from helpers.scripts import load_script
from vpp_service.evaluation.confidence import summarize


@pytest.fixture
def mr() -> ModuleType:
    return load_script("make_results")


def _doc(mr: ModuleType) -> dict:
    t = mr.CONF_TARGET
    rows = [{"dataset": "eth3d", "answered": 200, "bad": 8, "kept": [180, 150], "kept_bad": [4, 2]}]
    alone = [{"dataset": "eth3d", "answered": 100, "bad": 10, "kept": [70, 50], "kept_bad": [3, 1]}]
    summ = {
        "all": summarize(rows, (0.1, t)),
        "baseline": summarize(alone, (0.1, t)),
        "eth3d": summarize(rows, (0.1, t)),
    }
    meta = {"date_utc": "2026-01-01 00:00 UTC", "git_commit": "0123456789abcdef", "seconds": 3.0, "cpu": "CPU"}
    config = {"matcher": "census-sgm", "method": "vpp", "density": 0.05, "seed": 0, "limit": None}
    return {"meta": meta, "config": config, "thresholds": [0.1, t], "summary": summ, "results": rows}


def test_section_from_the_counts(mr):
    section = mr.render_confidence(_doc(mr))
    assert section.startswith(mr.CONF_MARKS[0]) and section.endswith(mr.CONF_MARKS[1])
    # at 0.5: 150 of 200 kept (75 %), 2 of them bad (1.33 %) against 8 of 200 (4 %): 67 % lower
    assert "At 0.5: 75.0 % kept, bad-2 4.00 -> 1.33 % (67 % lower)." in section
    assert "| 0.5 | 75.0 | 1.33 | 75.0 | 1.33 | 50.0 | 2.00 |" in section
    assert "| ETH3D two-view training, 1 scene(s) | 4.00 | 75.0 | 1.33 |" in section


def test_written_between_markers_and_kept_by_a_full_regeneration(mr, tmp_path):
    page = tmp_path / "results.md"
    page.write_text("# Results\n\nintro\n\n## Beside the paper\n\ntail\n")
    mr.write_confidence(_doc(mr), tmp_path)
    first = page.read_text()
    assert first.index(mr.CONF_MARKS[0]) < first.index("## Beside the paper") and "intro" in first and "tail" in first
    mr.write_confidence(_doc(mr), tmp_path)  # a second run replaces its section, nothing else
    assert page.read_text() == first
    stored = json.loads((tmp_path / "results" / "results_confidence.json").read_text())
    assert mr.render_confidence(stored) == mr.render_confidence(_doc(mr))
