"""Evaluation runner, reports and the ``vpp-service eval`` command, end to end with real matchers."""

from __future__ import annotations

import io
import json
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from helpers.shared_data import need_shared
from vpp_service.cli import main
from vpp_service.datasets import open_dataset
from vpp_service.evaluation import (
    ProgressBar,
    default_max_disparity,
    markdown_report,
    run_evaluation,
    summarize,
    write_json,
)
from vpp_service.evaluation.report import json_safe
from vpp_service.evaluation.runner import METHODS
from vpp_service.matchers import build_matcher, fill_holes
from vpp_service.matchers.opencv import SGBM
from vpp_service.metrics import compute_metrics
from vpp_service.sources.sensors import build_sensor
from vpp_service.sources.synthetic import make_scene


def need_midd06() -> Path:
    return need_shared("middlebury2005_2006_thirdsize")


@pytest.fixture(scope="module")
def scenes():
    return [make_scene(120, 180, seed=s, texture="weak", noise=2.0, max_disparity=32) for s in (0, 1)]


def test_rows_and_reference_equality(scenes):
    rows = run_evaluation(scenes, "sgbm", ["baseline", "vpp"], [0.05], seed=3)
    assert [(r["scene"], r["method"]) for r in rows] == [
        ("synthetic-planes-0", "baseline"),
        ("synthetic-planes-0", "vpp"),
        ("synthetic-planes-1", "baseline"),
        ("synthetic-planes-1", "vpp"),
    ]
    for r, f in zip(rows, [scenes[0], scenes[0], scenes[1], scenes[1]], strict=True):
        for k in ("bad1", "bad2", "bad3", "bad4", "avg", "rms", "n", "bad2_nocc", "n_points", "ms", "density"):
            assert k in r
        assert r["matcher"] == "sgbm" and r["sensor"] == "uniform" and r["dataset"] == "synthetic"
        md = r["max_disparity"]
        assert md % 16 == 0 and md - 16 <= np.nanmax(f.gt_disparity) < md  # next multiple of 16 above GT
    # same points for every method
    assert rows[0]["n_points"] == rows[1]["n_points"] > 0
    # the baseline row equals scoring the matcher by hand (holes filled first)
    f = scenes[0]
    md = rows[0]["max_disparity"]
    disp = build_matcher("sgbm", {"max_disparity": md}).compute(f.left, f.right)
    ref = compute_metrics(fill_holes(disp), f.gt_disparity)
    for k in ("bad2", "avg", "rms", "n"):
        assert rows[0][k] == pytest.approx(ref[k])
    ref_nocc = compute_metrics(fill_holes(disp), f.gt_disparity, mask=f.nocc_mask)
    assert rows[0]["bad2_nocc"] == pytest.approx(ref_nocc["bad2"])
    # the VPP row equals project + match on the sensor's points
    from vpp_service.vpp import VPPConfig, project

    sparse = build_sensor("uniform", {"density": 0.05}).simulate(f, 3).sparse_disparity
    painted = project(f.left, f.right, sparse, VPPConfig(), seed=3)
    vdisp = build_matcher("sgbm", {"max_disparity": md}).compute(painted.left, painted.right)
    assert rows[1]["bad2"] == pytest.approx(compute_metrics(fill_holes(vdisp), f.gt_disparity)["bad2"])
    assert rows[1]["n_points"] == int(np.isfinite(sparse).sum())


def test_vpp_helps_on_weak_texture(scenes):
    s = summarize(run_evaluation(scenes, "sgbm", "baseline,vpp", 0.05))
    assert s["vpp"]["bad2"] < s["baseline"]["bad2"] - 1.0
    assert s["vpp"]["avg"] < s["baseline"]["avg"]


def test_guided_and_vpp_improve_on_real_scene():
    ds = open_dataset("auto", need_midd06()).select(["Art"])
    rows = run_evaluation(ds, "census-sgm", ["baseline", "guided", "vpp"], [0.05], seed=0)
    by = {r["method"]: r for r in rows}
    assert by["baseline"]["dataset"] == "middlebury2006" and by["baseline"]["max_disparity"] == 80
    for m in ("guided", "vpp"):
        assert by[m]["bad2"] < by["baseline"]["bad2"] - 1.0, (m, by[m]["bad2"], by["baseline"]["bad2"])
        assert by[m]["bad2_nocc"] < by["baseline"]["bad2_nocc"]
        assert by[m]["avg"] < by["baseline"]["avg"]


def test_density_sweep_summary_and_progress(scenes):
    out = io.StringIO()
    rows = run_evaluation(scenes[:1], "sgbm", ["baseline", "vpp"], [0.01, 0.05], progress=ProgressBar(out))
    assert len(rows) == 4 and {r["density"] for r in rows} == {0.01, 0.05}
    base = [r for r in rows if r["method"] == "baseline"]
    assert base[0]["bad2"] == base[1]["bad2"]  # computed once, reported per density
    s = summarize(rows)
    assert set(s["vpp"]) == {"0.01", "0.05"} and "bad2" in s["vpp"]["0.05"]
    lines = out.getvalue().splitlines()
    assert lines[0].startswith("[1/3] synthetic-planes-0 sgbm baseline")
    assert lines[2].startswith("[3/3] synthetic-planes-0 sgbm vpp 0.05")
    assert lines[-1].startswith("[3/3] done")


@pytest.mark.parametrize(("sensor", "opts"), [("lidar", {"nominal_f": 300.0}), ("tof", {"grid_w": 40, "grid_h": 30})])
def test_other_sensors_report_measured_density(scenes, sensor, opts):
    rows = run_evaluation(scenes[:1], "sgbm", ["vpp"], None, sensor, sensor_options=opts)
    r = rows[0]
    assert r["sensor"] == sensor and 0 < r["density"] < 0.2
    assert r["n_points"] == pytest.approx(r["density"] * np.isfinite(scenes[0].gt_disparity).sum())


def test_frame_sensor_uses_own_points(scenes):
    f = build_sensor("uniform", {"density": 0.02}).simulate(scenes[0], 5)
    rows = run_evaluation([f], "sgbm", ["vpp"], None, "frame")
    assert rows[0]["n_points"] == int(np.isfinite(f.sparse_disparity).sum())


def test_runner_errors(scenes):
    with pytest.raises(ValueError, match="'sgbm' has none"):
        run_evaluation(scenes, "sgbm", ["guided"], [0.05])
    with pytest.raises(ValueError, match="methods"):
        run_evaluation(scenes, "sgbm", ["magic"], [0.05])
    with pytest.raises(ValueError, match="only the uniform sensor"):
        run_evaluation(scenes, "sgbm", ["vpp"], [0.05], "lidar")
    with pytest.raises(ValueError, match="densities"):
        run_evaluation(scenes, "sgbm", ["vpp"], [0.0])
    with pytest.raises(ValueError, match="gt_disparity"):
        run_evaluation([scenes[0].with_(gt_disparity=None)], "sgbm", ["baseline"], [0.05])
    with pytest.raises(ValueError, match="unknown matcher"):
        run_evaluation(scenes, "nope", ["baseline"], [0.05])
    with pytest.raises(ValueError, match="sparse_disparity"):
        run_evaluation(scenes[:1], "sgbm", ["vpp"], None, "frame")
    with pytest.raises(TypeError, match="frames_or_dataset"):
        run_evaluation(3, "sgbm", ["baseline"], [0.05])
    with pytest.raises(ValueError, match="no frames"):
        run_evaluation([], "sgbm", ["baseline"], [0.05])


def test_default_max_disparity():
    assert default_max_disparity(np.array([[np.nan, 3.0]]), 500) == 16
    assert default_max_disparity(np.array([[16.0]]), 500) == 32
    assert default_max_disparity(np.array([[70.3]]), 500) == 80
    assert default_max_disparity(np.array([[70.3]]), 60) == 59


def test_reports(tmp_path, scenes):
    rows = run_evaluation(scenes[:1], "sgbm", ["baseline", "vpp"], [0.05])
    doc = write_json(tmp_path / "r.json", rows, {"k": 1})
    back = json.loads((tmp_path / "r.json").read_text())
    assert back == doc and back["config"] == {"k": 1} and len(back["results"]) == 2
    assert back["summary"]["vpp"]["bad2"] == pytest.approx(rows[1]["bad2"])
    md = markdown_report(rows, per_scene=True)
    assert "## synthetic - sgbm (1 scenes, sensor uniform)" in md
    assert md.count("\n| baseline |") == 1 and "### Per scene" in md


def test_json_safe():
    doc = json_safe({"a": (np.float32(1.5), float("nan")), 2: np.int64(3), "b": [None, True, "x"]})
    assert doc == {"a": [1.5, None], "2": 3, "b": [None, True, "x"]}
    assert type(doc["2"]) is int
    with pytest.raises(TypeError, match="object is not JSON serializable"):
        json_safe({"x": object()})


def test_summarize_sweep_puts_rows_without_density_last():
    rows = [
        {"scene": "a", "method": "vpp", "sensor": "uniform", "density": 0.1, "bad2": 4.0},
        {"scene": "a", "method": "vpp", "sensor": "uniform", "density": 0.05, "bad2": 6.0},
        {"scene": "a", "method": "vpp", "sensor": "lidar", "density": None, "bad2": 8.0},
    ]
    s = summarize(rows)
    assert list(s["vpp"]) == ["0.05", "0.1", "measured"]
    assert s["vpp"]["measured"]["bad2"] == 8.0 and s["vpp"]["0.05"]["bad2"] == 6.0


def test_cli_end_to_end_real_scenes(tmp_path, capsys):
    root = need_midd06()
    out = tmp_path / "out.json"
    rc = main(
        [
            "eval",
            "--dataset",
            "auto",
            "--root",
            str(root),
            "--scenes",
            "Art,Wood2",
            "--matcher",
            "sgbm",
            "--methods",
            "baseline,vpp",
            "--density",
            "0.01,0.05",
            "--seed",
            "1",
            "--json",
            str(out),
            "--markdown",
            str(tmp_path / "out.md"),
            "--patch",
            "5",
            "--alpha",
            "0.5",
            "--no-splat",
        ]
    )
    assert rc == 0
    doc = json.loads(out.read_text())
    assert {r["scene"] for r in doc["results"]} == {"Art", "Wood2"} and len(doc["results"]) == 8
    assert doc["config"]["vpp"]["patch"] == 5 and doc["config"]["vpp"]["splat"] is False
    assert set(doc["summary"]) == {"baseline", "vpp"} and set(doc["summary"]["vpp"]) == {"0.01", "0.05"}
    for r in doc["results"]:
        assert r["dataset"] == "middlebury2006" and 0 <= r["bad2"] <= 100 and r["n"] > 0
    png = cv2.imread(str(tmp_path / "out.png"))
    assert png is not None and png.shape[0] > 100
    md = (tmp_path / "out.md").read_text()
    assert "middlebury2006 - sgbm" in md and "| vpp | 0.05 |" in md
    captured = capsys.readouterr()
    assert "| vpp | 0.01 |" in captured.out and "[1/6] Art sgbm baseline" in captured.err


def test_cli_synthetic_and_errors(tmp_path, capsys):
    rc = main(
        [
            "eval",
            "--dataset",
            "synthetic",
            "--limit",
            "1",
            "--matcher",
            "sgbm",
            "--methods",
            "baseline,vpp",
            "--quiet",
            "--json",
            str(tmp_path / "s.json"),
        ]
    )
    assert rc == 0
    doc = json.loads((tmp_path / "s.json").read_text())
    assert [r["method"] for r in doc["results"]] == ["baseline", "vpp"] and "bad2" in doc["summary"]["vpp"]
    assert {(r["engine"], r["device"], r["precision"]) for r in doc["results"]} == {("opencv", "cpu", "int16")}
    assert capsys.readouterr().err == ""
    assert main(["eval", "--matcher", "sgbm"]) == 2
    assert "--root" in capsys.readouterr().err
    assert main(["eval", "--root", str(tmp_path), "--methods", "baseline"]) == 2
    assert "no known dataset layout" in capsys.readouterr().err
    assert main(["eval", "--dataset", "synthetic", "--limit", "1", "--matcher", "sgbm", "--methods", "guided"]) == 2
    assert "guidance" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["eval", "--dataset", "synthetic", "--density", "2"])


class SlowFirstSGBM(SGBM):
    """SGBM whose first pair costs ``first_s`` more, as a network's engine compiling on its first input does."""

    first_s = 0.6

    def __init__(self, options=None) -> None:
        super().__init__(options)
        self.calls = 0

    def _compute(self, left, right, hints):
        self.calls += 1
        if self.calls == 1:
            time.sleep(self.first_s)
        return super()._compute(left, right, hints)


def test_the_matchers_warm_up_is_charged_to_no_method(scenes):
    """One untimed pass before any method is timed: the first method's ms is not the engine's start-up."""
    m = SlowFirstSGBM({"max_disparity": 48})
    rows = run_evaluation(scenes[:1], m, ["baseline", "vpp"], [0.05])
    assert m.calls == 3  # the warm-up, then one per method
    by_method = {r["method"]: r["ms"] for r in rows}
    assert by_method["baseline"] < SlowFirstSGBM.first_s * 1000 / 2, by_method
    assert by_method["vpp"] < SlowFirstSGBM.first_s * 1000 / 2, by_method


def test_rows_name_the_engine_device_and_precision_that_ran(scenes):
    rows = run_evaluation(scenes[:1], "census-sgm", ["baseline", "vpp"], [0.05])
    from vpp_service.matchers import census_sgm

    engine = "cython" if census_sgm._k is census_sgm.portable else "cython-avx2"
    assert {(r["engine"], r["device"], r["precision"]) for r in rows} == {(engine, "cpu", "int16")}


@pytest.mark.parametrize(("matcher", "methods"), [("sgbm", ["baseline", "vpp"]), ("census-sgm", list(METHODS))])
def test_eval_default_methods_are_the_ones_the_matcher_supports(tmp_path, capsys, matcher, methods):
    """Without --methods: guided only with a matcher that has guided stereo; the skip is said, not an error."""
    out = tmp_path / "r.json"
    argv = ["eval", "--dataset", "synthetic", "--limit", "1", "--matcher", matcher, "--quiet", "--json", str(out)]
    assert main(argv) == 0
    err = capsys.readouterr().err
    assert [r["method"] for r in json.loads(out.read_text())["results"]] == methods
    skipped = "methods baseline,vpp (guided skipped: 'sgbm' has no guided stereo"
    assert (skipped in err) == (matcher == "sgbm")


class InterruptAt:
    """A progress callback that raises KeyboardInterrupt (what Ctrl-C does) at its ``n``-th call."""

    def __init__(self, n: int) -> None:
        self.n, self.calls = n, 0

    def __call__(self, done: int, total: int, label: str) -> None:
        self.calls += 1
        if self.calls == self.n:
            raise KeyboardInterrupt


def test_an_interrupted_evaluation_keeps_the_rows_of_finished_scenes():
    from vpp_service.evaluation.runner import EvaluationInterrupted

    frames = [make_scene(height=48, width=96, max_disparity=16, seed=i) for i in range(3)]
    with pytest.raises(EvaluationInterrupted) as info:  # 2 steps per scene: the 4th is scene 2's vpp
        run_evaluation(frames, "bm", ("baseline", "vpp"), [0.05], progress=InterruptAt(4))
    exc = info.value
    assert (exc.scenes_done, exc.scenes_total) == (1, 3)
    full = run_evaluation(frames[:1], "bm", ("baseline", "vpp"), [0.05])
    assert [(r["scene"], r["method"]) for r in exc.rows] == [(r["scene"], r["method"]) for r in full]
    assert [r["bad2"] for r in exc.rows] == [r["bad2"] for r in full]


@pytest.mark.parametrize(("at", "scenes_done"), [(1, 0), (5, 2)])
def test_eval_ctrl_c_writes_what_finished_marked_partial(tmp_path, monkeypatch, capsys, at, scenes_done):
    from vpp_service import evaluation

    monkeypatch.setattr(evaluation, "ProgressBar", lambda stream: InterruptAt(at))
    out_json, out_md = tmp_path / "r.json", tmp_path / "r.md"
    argv = ["eval", "--dataset", "synthetic", "--limit", "3", "--matcher", "bm", "--methods", "baseline,vpp"]
    rc = main([*argv, "--json", str(out_json), "--markdown", str(out_md)])
    err = capsys.readouterr().err
    assert rc == 130
    if scenes_done == 0:
        assert "nothing written" in err and not out_json.exists() and not out_md.exists()
        return
    doc = json.loads(out_json.read_text())
    assert doc["config"]["partial"] == {"scenes_done": 2, "scenes_total": 3}
    assert len({r["scene"] for r in doc["results"]}) == 2 and len(doc["results"]) == 4
    assert "PARTIAL: interrupted after 2 of 3 scenes" in out_md.read_text()
    assert "2 of 3 scenes finished" in err and str(out_json) in err


def test_cli_offset_lidar_and_depth_filter(tmp_path, capsys):
    def run(*extra):
        out = tmp_path / f"{len(extra)}-{'-'.join(extra)[:40]}.json".replace("/", "_")
        args = ["eval", "--dataset", "synthetic", "--limit", "1", "--matcher", "sgbm", "--methods", "vpp"]
        assert main([*args, "--sensor", "lidar", "--quiet", "--json", str(out), *extra]) == 0
        return json.loads(out.read_text())

    auto = run("--sensor-opt", "pose=kitti", "--sensor-opt", "nominal_f=300")
    off = run("--sensor-opt", "pose=[0.1,-0.05,-0.2]", "--sensor-opt", "nominal_f=300", "--depth-filter", "none")
    assert "see_through" in auto["results"][0] and "see_through" not in off["results"][0]
    assert auto["config"]["sensor_options"]["pose"] == "kitti"
    assert off["config"]["depth_filter"] == {"mode": "none"}
    tuned = run("--sensor-opt", "pose=kitti", "--sensor-opt", "nominal_f=300", "--depth-filter-opt", "window_w=31")
    assert tuned["results"][0]["see_through"] >= auto["results"][0]["see_through"]
    bad = ["eval", "--dataset", "synthetic", "--limit", "1", "--sensor", "lidar", "--depth-filter-opt", "window_w=2"]
    assert main(bad) == 2
    assert "window_w" in capsys.readouterr().err
