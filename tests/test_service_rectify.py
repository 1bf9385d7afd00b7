"""A rig that sends raw, distorted frames: the service with ``[rectify]`` answers as on the rectified pair.

The raw pairs are synthesised from real Middlebury scenes with a known, mild calibration
(:mod:`helpers.raw_rig`): plumb_bob ``k1 = -0.12``, rotations under 1 degree. Played through
the whole service (files source, SGBM, no VPP), bad-2 on answered pixels must come within 2
points of the same scene played rectified; without ``[rectify]`` the raw pair is hopeless.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from helpers.raw_rig import write_raw_scene, write_rig_yamls
from helpers.shared_data import need_shared
from vpp_service.cli import EXIT_STARTUP, main
from vpp_service.service.app import run_service
from vpp_service.service.config import validate_config

SCENES = ("Art", "Books", "Moebius")
ROOT = "middlebury2005_2006_thirdsize"


def _config(root: Path, out: Path, rectify: dict[str, str] | None) -> dict[str, object]:
    data: dict[str, object] = {
        "service": {"out": str(out), "summary": False},
        "zenoh": {"enabled": False},
        "source": {"type": "files", "root": str(root), "dataset": "middlebury2006", "sensor": "none"},
        "vpp": {"enabled": False},
        "matcher": {"name": "sgbm", "max_disparity": 96},
    }
    if rectify is not None:
        data["rectify"] = rectify
    return data


def _bad2(data: dict[str, object]) -> tuple[float, dict[str, int]]:
    status = run_service(validate_config(data), stream=None)
    return status["metrics"]["last"].get("bad2_answered", float("nan")), status["counters"]


@pytest.mark.parametrize("scene", SCENES)
def test_raw_frames_with_rectify_match_the_rectified_pair(tmp_path, scene):
    raw_root, lp, rp = write_raw_scene(tmp_path, need_shared(ROOT), scene)
    rect_root = tmp_path / "rect"
    rect_root.mkdir()
    (rect_root / scene).symlink_to(need_shared(ROOT) / scene)

    reference, _ = _bad2(_config(rect_root, tmp_path / "o1", None))
    rectified, counters = _bad2(_config(raw_root, tmp_path / "o2", {"left": str(lp), "right": str(rp)}))
    unrectified, _ = _bad2(_config(raw_root, tmp_path / "o3", None))

    print(f"{scene}: bad-2 {reference:.2f} % rectified, {rectified:.2f} % raw + rectify, {unrectified:.2f} % raw")
    assert counters["processed"] == 1 and counters["rejected"] == 0
    assert rectified <= reference + 2.0, f"{scene}: bad-2 {rectified:.2f} % raw+rectify vs {reference:.2f} % rectified"
    assert unrectified > reference + 10.0  # the raw pair matched as if rectified: what [rectify] fixes


def test_a_frame_of_another_size_is_rejected_and_counted(tmp_path, caplog):
    root = tmp_path / "rect"
    root.mkdir()
    (root / "Art").symlink_to(need_shared(ROOT) / "Art")
    lp, rp = write_rig_yamls(tmp_path, 320, 240)
    with caplog.at_level("WARNING"):
        _, counters = _bad2(_config(root, tmp_path / "o", {"left": str(lp), "right": str(rp)}))
    assert counters["rejected"] == 1 and counters["processed"] == 0 and counters["errors"] == 0
    assert any("the [rectify] calibration is for 320x240" in r.getMessage() for r in caplog.records)


def test_check_names_a_nan_calibration_and_exits_2(tmp_path, capsys):
    lp, rp = write_rig_yamls(tmp_path, 320, 240)
    rp.write_text(re.sub(r"(camera_matrix:\n  rows: 3\n  cols: 3\n  data: \[)[^,]+", r"\1.nan", rp.read_text()))
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[zenoh]\nenabled = false\n[rectify]\nleft = "{lp}"\nright = "{rp}"\n')
    rc = main(["run", "--config", str(cfg), "--out", str(tmp_path / "o"), "--check"])
    err = capsys.readouterr().err
    assert rc == EXIT_STARTUP
    assert err.strip() == f"vpp-service run: error: rectify: {rp}: K holds a NaN or infinite value"
