"""deploy/rigs/: every rig preset passes ``vpp-service run --check`` and says which topics it reads."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import pytest

from vpp_service.cli import main
from vpp_service.transport.ros2 import keys

ROOT = Path(__file__).resolve().parents[1]
RIGS = ROOT / "deploy" / "rigs"
PRESETS = sorted(RIGS.glob("*.toml"))


def test_the_documented_presets_exist():
    assert {p.name for p in PRESETS} >= {"realsense-d4xx.toml", "zed.toml", "oak-d.toml", "diy-stereo.toml"}
    assert (RIGS / "README.md").is_file()
    for p in PRESETS:
        assert p.name in (RIGS / "README.md").read_text(), f"{p.name} missing from deploy/rigs/README.md"


@pytest.mark.parametrize("preset", PRESETS, ids=lambda p: p.stem)
def test_preset_passes_the_check(preset, monkeypatch, capsys):
    """``vpp-service run --config deploy/rigs/X.toml --check`` from the repository root exits 0."""
    monkeypatch.chdir(ROOT)  # the presets' calibration paths are relative to where the service runs
    assert main(["run", "--config", str(preset.relative_to(ROOT)), "--check"]) == 0
    cfg = json.loads(capsys.readouterr().out)
    comments = "\n".join(line for line in preset.read_text().splitlines() if line.lstrip().startswith("#"))
    assert f"vpp-service run --config deploy/rigs/{preset.name} --check" in comments
    src = cfg["source"]
    if src["type"] == "ros2":  # every topic it subscribes to is named in the preset's header, fully qualified
        for key in ("left_image", "left_info", "right_image", "right_info"):
            topic = keys.fully_qualified(src["namespace"], src[key])
            assert re.search(rf"(^|\s){re.escape(topic)}(\s|$)", comments, re.MULTILINE), f"{key}: {topic}"
        if src["depth_type"] != "none":
            topic = keys.fully_qualified(src["namespace"], src["depth_topic"])
            assert topic in comments, f"depth_topic: {topic}"
    else:
        assert f"{cfg['service']['prefix']}/{cfg['service']['rig']}/in/frame" in comments


def test_a_broken_calibration_fails_the_diy_check(tmp_path, monkeypatch, capsys):
    """The check reads the preset's camera_info YAMLs: one with a NaN is exit 2, naming the file."""
    rig = tmp_path / "deploy" / "rigs"
    shutil.copytree(RIGS, rig)
    left = rig / "diy" / "left.yaml"
    left.write_text(left.read_text().replace("data: [612.4,", "data: [.nan,"))
    monkeypatch.chdir(tmp_path)
    assert main(["run", "--config", "deploy/rigs/diy-stereo.toml", "--check"]) == 2
    assert "left.yaml" in capsys.readouterr().err
