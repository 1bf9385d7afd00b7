"""A service started again in its output folder resumes there, keeping the previous run's outputs."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from helpers.toml import toml_dumps
from vpp_service.cli import EXIT_STARTUP, main
from vpp_service.service.config import DEFAULT_CONFIG, load_config, validate_config
from vpp_service.service.resume import KEEP_SUMMARIES, resume_outputs, resumes

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "deploy" / "config.example.toml"
UNIT = ROOT / "deploy" / "vpp-service@.service"


def small_config(tmp_path: Path, **service) -> dict:
    """Three frames of a small synthetic scene, no Zenoh, a Rerun recording in out."""
    return {
        "service": {"out": str(tmp_path / "out"), "summary": False, **service},
        "zenoh": {"enabled": False},
        "source": {
            "type": "sim",
            "scene": "synthetic",
            "scene_options": {"height": 48, "width": 96, "max_disparity": 16},
            "count": 3,
        },
        "matcher": {"name": "bm", "max_disparity": 16},
        "sinks": [{"type": "rerun", "mode": "save", "path": "{out}/vpp.rrd", "max_files": 2}],
    }


@pytest.mark.parametrize(
    ("source", "service", "expect"),
    [
        ("sim", {}, False),  # the one-shot default: refuse
        ("files", {}, False),
        ("zenoh", {}, True),  # a network source: a service
        ("ros2", {}, True),
        ("sim", {"resume": True}, True),
        ("zenoh", {"resume": False}, False),
        ("zenoh", {"overwrite": True}, False),  # overwrite replaces: nothing to keep
        ("sim", {"resume": True, "overwrite": True}, False),
    ],
)
def test_who_resumes(source, service, expect):
    data = json.loads(json.dumps(DEFAULT_CONFIG))
    data["service"].update(service)
    data["source"] = {"type": source, "root": "."} if source == "files" else {"type": source}
    assert resumes(validate_config(data)) is expect


def test_resume_rejects_other_values():
    from vpp_service.settings import SettingsError

    with pytest.raises(SettingsError, match=r"service\.resume"):
        load_config(None, {"service": {"resume": "yes"}})


def test_resume_outputs_rotates_the_summary_and_the_recording(tmp_path):
    cfg = validate_config(small_config(tmp_path))
    out = tmp_path / "out"
    out.mkdir()
    assert resume_outputs(cfg) == []  # nothing there yet
    for run in range(KEEP_SUMMARIES + 2):
        (out / "summary.json").write_text(json.dumps({"run": run}))
        (out / "vpp.rrd").write_text(f"rrd {run}")
        moved = resume_outputs(cfg)
        assert moved == [
            f"{out / 'summary.json'} -> {out / 'summary.1.json'}",
            f"{out / 'vpp.rrd'} -> {out / 'vpp.1.rrd'}",
        ]
    summaries = sorted(out.glob("summary.*.json"), key=lambda p: int(p.name.split(".")[1]))
    assert [json.loads(p.read_text())["run"] for p in summaries] == list(
        range(KEEP_SUMMARIES + 1, 2, -1)
    )  # the newest 9
    assert len(summaries) == KEEP_SUMMARIES - 1  # with the next run's own summary.json: KEEP_SUMMARIES
    assert sorted(p.name for p in out.glob("vpp*.rrd")) == ["vpp.1.rrd"]  # the sink's max_files = 2


def test_run_resume_keeps_the_previous_run(tmp_path, capsys):
    cfg = tmp_path / "run.toml"
    cfg.write_text(toml_dumps(small_config(tmp_path)))
    out = tmp_path / "out"
    assert main(["run", "--config", str(cfg), "--no-summary"]) == 0
    first = json.loads((out / "summary.json").read_text())
    rrd = (out / "vpp.rrd").read_bytes()
    assert main(["run", "--config", str(cfg), "--no-summary"]) == EXIT_STARTUP  # sim: a one-shot run refuses
    assert "--resume" in capsys.readouterr().err
    assert main(["run", "--config", str(cfg), "--no-summary", "--resume"]) == 0
    assert "resuming in" in capsys.readouterr().err
    assert json.loads((out / "summary.1.json").read_text()) == first
    assert (out / "vpp.1.rrd").read_bytes() == rrd
    second = json.loads((out / "summary.json").read_text())
    assert second["counters"]["processed"] == 3 and second["uptime_s"] != first["uptime_s"]


def test_the_example_config_started_twice_in_one_folder_resumes(tmp_path, zenoh_endpoint, monkeypatch):
    """deploy/config.example.toml, as a unit runs it: the second start must not exit 2; the first summary survives."""
    monkeypatch.chdir(tmp_path)  # the example's out = "vpp-run", relative as under the unit's WorkingDirectory
    argv = ["run", "--config", str(EXAMPLE), "--zenoh-listen", zenoh_endpoint, "--max-frames", "2", "--no-summary"]
    assert load_config(EXAMPLE).zenoh.multicast_scouting is False
    assert main(argv) == 0
    out = tmp_path / "vpp-run"
    first = (out / "summary.json").read_text()
    assert json.loads(first)["counters"]["processed"] == 2
    assert main(argv) == 0
    assert (out / "summary.1.json").read_text() == first
    assert json.loads((out / "summary.json").read_text())["counters"]["processed"] == 2
    assert (out / "vpp.rrd").is_file() and (out / "vpp.1.rrd").is_file()


def test_the_systemd_unit_resumes():
    (exec_start,) = [line for line in UNIT.read_text().splitlines() if line.startswith("ExecStart=")]
    assert exec_start.split()[1:3] == ["run", "--config"] and "--resume" in exec_start.split()
