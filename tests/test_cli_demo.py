"""``vpp-service demo``: the three reported numbers, a figure with a colour bar and error maps; error_map."""

from __future__ import annotations

import json
import time

import cv2
import numpy as np
import pytest

from vpp_service.cli import main
from vpp_service.evaluation.report import error_map
from vpp_service.matchers import MATCHERS
from vpp_service.matchers.opencv import SGBM
from vpp_service.metrics import compute_metrics


def test_demo_reports_the_three_numbers_and_draws_the_figure(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    summary = json.loads((tmp_path / "summary.json").read_text())
    for method in ("baseline", "vpp"):
        s = summary[method]
        assert set(s) == {"bad2_answered", "density", "bad2_filled", "filled"}
        assert 0 < s["density"] <= 100 and s["filled"]["bad2"] == pytest.approx(s["bad2_filled"])
        row = next(line for line in printed.splitlines() if line.startswith(method))
        assert f"{s['bad2_answered']:.2f}" in row and f"{s['density']:.1f}" in row and f"{s['bad2_filled']:.2f}" in row
    assert summary["vpp"]["bad2_filled"] < summary["baseline"]["bad2_filled"]  # against ground truth: VPP helps
    assert "holes filled before scoring" in printed
    figure = cv2.imread(str(tmp_path / "demo.png"))
    assert figure is not None and figure.shape[0] > 500 and figure.shape[1] > 500
    assert not (tmp_path / "disparity_baseline.png").exists()  # the bare colour maps are gone


class SlowFirstSGBM(SGBM):
    """SGBM whose first pair costs 0.6 s more, as a network's engine compiling on its first input does."""

    name = "sgbm-slow-first"
    calls = 0

    def _compute(self, left, right, hints):
        type(self).calls += 1
        if type(self).calls == 1:
            time.sleep(0.6)
        return super()._compute(left, right, hints)


def test_demo_warms_the_matcher_up_before_timing(tmp_path, monkeypatch, capsys):
    """The baseline's ms is the matcher's, not its start-up's (PSMNet's first pair: seconds)."""
    monkeypatch.setitem(MATCHERS._items, SlowFirstSGBM.name, SlowFirstSGBM)
    monkeypatch.setattr(SlowFirstSGBM, "calls", 0)
    assert main(["demo", "--out", str(tmp_path), "--matcher", SlowFirstSGBM.name]) == 0
    capsys.readouterr()
    ms = json.loads((tmp_path / "summary.json").read_text())["ms"]
    assert SlowFirstSGBM.calls == 3  # warm-up, baseline, VPP
    assert ms["baseline"] < 300 and ms["vpp_match"] < 300, ms


def test_demo_refuses_to_overwrite_a_previous_demo(tmp_path, capsys):
    (tmp_path / "summary.json").write_text("{}")  # a previous demo's
    assert main(["demo", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert f"{str(tmp_path)!r} holds a previous demo's files (summary.json); pass --overwrite" in err
    assert (tmp_path / "summary.json").read_text() == "{}" and not (tmp_path / "demo.png").exists()
    assert main(["demo", "--out", str(tmp_path), "--overwrite"]) == 0
    assert json.loads((tmp_path / "summary.json").read_text())["matcher"] == "sgbm"


def test_failed_demo_leaves_no_folder_it_created(tmp_path, capsys, monkeypatch):
    out = tmp_path / "new" / "demo"
    assert main(["demo", "--out", str(out), "--matcher", "nope"]) == 2
    assert "unknown matcher 'nope'" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []

    from vpp_service.evaluation import report

    def disk_full(path, *args, **kwargs):
        raise OSError(28, "No space left on device", str(path))

    monkeypatch.setattr(report, "plot_comparison", disk_full)  # the disk fills while the demo writes
    assert main(["demo", "--out", str(out)]) == 2
    assert "No space left on device" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []  # new/ and new/demo/ with the painted pair already in it: gone
    keep = tmp_path / "mine"
    keep.mkdir()
    (keep / "notes.txt").write_text("mine")
    assert main(["demo", "--out", str(keep)]) == 2
    assert [p.name for p in keep.iterdir()] == ["notes.txt"]  # the user's folder: only the partial files went


def plain_error_map(disp: np.ndarray, gt: np.ndarray, tau: float) -> np.ndarray:
    out = np.zeros((*gt.shape, 3), np.uint8)
    for y in range(gt.shape[0]):
        for x in range(gt.shape[1]):
            g, d = gt[y, x], disp[y, x]
            if not (np.isfinite(g) and g > 0):
                continue
            if not np.isfinite(d):
                out[y, x] = (128, 128, 128)
            elif abs(d - g) > tau:
                out[y, x] = (220, 40, 40)
            else:
                out[y, x] = (60, 170, 60)
    return out


@pytest.mark.parametrize("tau", [0.5, 2.0])
def test_error_map_matches_a_plain_loop(tau):
    rng = np.random.default_rng(3)
    gt = rng.uniform(0, 20, (9, 13)).astype(np.float32)
    gt[rng.random(gt.shape) < 0.2] = np.nan
    gt[0, 0] = 0.0
    disp = gt + rng.normal(0, 2, gt.shape).astype(np.float32)
    disp[rng.random(gt.shape) < 0.2] = np.nan
    np.testing.assert_array_equal(error_map(disp, gt, tau), plain_error_map(disp, gt, tau))
    red = (error_map(disp, gt, tau) == (220, 40, 40)).all(axis=2).sum()
    scored = np.isfinite(gt) & (gt > 0)
    assert red / scored.sum() * 100 + compute_metrics(disp, gt, taus=(tau,))["invalid"] == pytest.approx(
        compute_metrics(disp, gt, taus=(tau,))[f"bad{tau:g}"]
    )


def test_error_map_rejects_mismatched_shapes():
    with pytest.raises(ValueError, match="differ in shape"):
        error_map(np.zeros((2, 3), np.float32), np.zeros((3, 2), np.float32))
