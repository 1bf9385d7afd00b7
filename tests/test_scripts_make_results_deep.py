"""scripts/make_results.py --deep: its section of the page, placed between markers, the rest of the page kept."""

from __future__ import annotations

from types import ModuleType

import pytest

from helpers.scripts import load_script


@pytest.fixture
def mr() -> ModuleType:
    return load_script("make_results")


def _row(dataset: str, matcher: str, method: str, bad2: float, scene: str = "s") -> dict:
    return {
        "dataset": dataset,
        "scene": scene,
        "matcher": matcher,
        "sensor": "uniform",
        "density": 0.05,
        "method": method,
        "bad1": bad2 + 2,
        "bad2": bad2,
        "bad3": bad2 - 1,
        "bad4": bad2 - 2,
        "avg": 1.0,
        "ms": 4000.0,
        "n_points": 10,
    }


def _deep(mr: ModuleType) -> dict:
    rows = [_row("middlebury2006", "psmnet", "baseline", 20.0), _row("middlebury2006", "psmnet", "vpp", 10.0)]
    meta = {"date_utc": "d", "git_commit": "0" * 40, "seconds": 1.0, "cpu": "cpu", "usable_cores": 2}
    vpp = {"pattern": "random", "patch": 5, "uniform_patch": True, "alpha": 0.4, "occlusion": "fgd"}
    config = {"matcher": "psmnet", "model": "m.onnx", "model_sha256": "ab" * 32, "seed": 0, "vpp": vpp}
    return {"meta": {**meta, "engine": "openvino cpu f32, 2 threads"}, "config": config, "results": rows}


def test_the_deep_section_sits_between_markers_and_replaces_only_itself(mr):
    classic = {
        "summary": mr.summaries(
            [_row("middlebury2006", "census-sgm", m, b) for m, b in (("baseline", 10.0), ("vpp", 5.0))]
        )
    }
    section = mr.render_deep(_deep(mr), classic)
    assert section.startswith(mr.DEEP_MARKS[0]) and section.endswith(mr.DEEP_MARKS[1])
    lines = [line for line in section.splitlines() if line.startswith("| Middlebury")]
    assert [line.split(" | ")[1:3] for line in lines] == [
        ["census-sgm", "baseline"],
        ["census-sgm", "**vpp**"],
        ["psmnet", "baseline"],
        ["psmnet", "**vpp**"],
    ]
    assert "| 0.50 | 4.00 |" in lines[3] and "uniform patches" in section  # VPP/base bad-2, s/frame
    page = "# Results\n\ntext\n\n## Beside the paper\n\nmore\n"
    once = mr.splice_deep(page, section)
    assert once.index(section) < once.index("## Beside the paper") and once.count(mr.DEEP_MARKS[0]) == 1
    again = mr.splice_deep(once, section.replace("psmnet", "other"))
    assert again.count(mr.DEEP_MARKS[0]) == 1 and "other" in again
    assert again.replace(section.replace("psmnet", "other"), section) == once  # nothing else touched
