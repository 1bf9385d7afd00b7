"""The ``run`` sub-command: flags (Rerun, ROS 2) via the real parser, --check on paths, start-up and closing lines.

Damaged bags are played by the command itself (a subprocess).
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from pathlib import Path

import cv2
import numpy as np
import pytest

from helpers.cli import vpp_service_module_command
from helpers.damaged_bags import cut, garble, write_test_bag
from helpers.own_folder import own_scene, write_own_folder
from helpers.ros2_robot import StereoRig, write_bag
from vpp_service.cli import EXIT_STARTUP, build_parser, main
from vpp_service.cli.run import closing_line, overrides_from_args, startup_line
from vpp_service.fusion import fuse
from vpp_service.matchers import build_matcher
from vpp_service.metrics import compute_metrics
from vpp_service.service.config import DEFAULT_CONFIG, validate_config
from vpp_service.settings import SettingsError

ROOT = Path(__file__).resolve().parents[1]
CONFIGURED = {**DEFAULT_CONFIG, "sinks": [{"type": "zenoh"}, {"type": "rerun", "max_hz": 2.5, "path": "x.rrd"}]}


def sinks_for(*argv: str) -> list[tuple[str, object]]:
    args = build_parser().parse_args(["run", *argv])
    cfg = validate_config(overrides_from_args(CONFIGURED, args))
    return [(s.name, s.options) for s in cfg.sinks]


@pytest.mark.parametrize(
    ("argv", "mode", "where"),
    [
        (["--rerun-save", "y.rrd"], "save", ("path", "y.rrd")),
        (["--rerun-connect"], "connect", ("url", "rerun+http://127.0.0.1:9876/proxy")),
        (
            ["--rerun-connect", "rerun+http://10.0.0.5:9000/proxy"],
            "connect",
            ("url", "rerun+http://10.0.0.5:9000/proxy"),
        ),
        (["--rerun-serve"], "serve", ("grpc_port", 9876)),
        (["--rerun-serve", "9100"], "serve", ("grpc_port", 9100)),
        (["--rerun-spawn"], "spawn", ("mode", "spawn")),
    ],
)
def test_rerun_flags_choose_the_output_and_keep_other_options(argv, mode, where):
    sinks = sinks_for(*argv)
    assert [n for n, _ in sinks] == ["zenoh", "rerun"]
    opts = sinks[1][1]
    assert opts.mode == mode and getattr(opts, where[0]) == where[1]
    assert opts.max_hz == 2.5  # the configured sink's other options stay
    assert opts.bind == "127.0.0.1"


def test_headless_drops_rerun():
    assert [n for n, _ in sinks_for("--headless")] == ["zenoh"]
    assert [n for n, _ in sinks_for()] == ["zenoh", "rerun"]


def test_rerun_flags_exclude_each_other(capsys):
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args(["run", "--rerun-spawn", "--headless"])
    assert exc.value.code == 2 and "not allowed with" in capsys.readouterr().err


@pytest.mark.parametrize("argv", [["--pool"], ["--worker-id", "w0"]])
def test_the_retired_pool_options_are_unknown(capsys, argv):
    """The worker pool is gone (networks scale on Triton): its options are usage errors, exit 2."""
    with pytest.raises(SystemExit) as exc:
        main(["run", *argv, "--check"])
    assert exc.value.code == EXIT_STARTUP == 2
    assert f"unrecognized arguments: {' '.join(argv)}" in capsys.readouterr().err


def test_the_retired_pool_keys_are_unknown():
    for key, value in (("pool", True), ("pool_deadline_ms", 1000.0), ("worker_id", "w0")):
        with pytest.raises(SettingsError, match=f"service.{key}"):
            validate_config({**DEFAULT_CONFIG, "service": {key: value}})


def config(argv: list[str]):
    args = build_parser().parse_args(["run", *argv])
    return validate_config(overrides_from_args(DEFAULT_CONFIG, args))


def test_ros_namespace_and_domain_reach_source_and_sinks():
    cfg = config(
        ["--source", "ros2", "--sink", "ros2", "--sink", "zenoh", "--ros-namespace", "/r", "--ros-domain", "5"]
    )
    assert cfg.source.name == "ros2" and cfg.source.options.namespace == "/r" and cfg.source.options.domain_id == 5
    ros_sink = next(s for s in cfg.sinks if s.name == "ros2")
    assert ros_sink.options.namespace == "/r" and ros_sink.options.domain_id == 5
    assert "namespace" not in next(s for s in cfg.sinks if s.name == "zenoh").raw


def test_bad_ros_flags_rejected():
    with pytest.raises(SettingsError, match="domain_id"):
        config(["--source", "ros2", "--ros-domain", "999"])
    with pytest.raises(SettingsError, match="namespace"):
        config(["--sink", "ros2", "--ros-namespace", "no/slash"])


def test_rosbag_flag(tmp_path):
    img = np.zeros((4, 6, 3), np.uint8)
    write_bag(str(tmp_path / "bag"), "mcap", StereoRig(img, img, 10.0, 0.1, 2.5, 2.5, 1.5, np.zeros((0, 3))), [1])
    cfg = config(["--rosbag", str(tmp_path / "bag"), "--ros-namespace", "/cam"])
    assert cfg.source.name == "rosbag2" and cfg.source.options.path == str(tmp_path / "bag")
    assert cfg.source.options.namespace == "/cam"
    with pytest.raises(SettingsError, match="path"):
        config(["--rosbag", str(tmp_path / "missing")])


def _check(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    rc = main(["run", *argv, "--check"])
    captured = capsys.readouterr()
    return rc, captured.out, captured.err


def test_check_passes_the_default(tmp_path, capsys):
    rc, out, _ = _check(capsys, "--out", str(tmp_path / "new"))  # out is created at start: fine missing
    assert rc == 0 and json.loads(out)["service"]["out"] == str(tmp_path / "new")
    assert not (tmp_path / "new").exists()  # --check creates nothing


def test_check_reports_a_missing_dataset_root(tmp_path, capsys):
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[source]\ntype = "files"\nroot = "{tmp_path / "nowhere"}"\n')
    rc, out, err = _check(capsys, "--config", str(cfg))
    assert rc == EXIT_STARTUP and out == ""
    assert err.strip() == f"vpp-service run: error: source.root: no such folder: {tmp_path / 'nowhere'}"


def test_check_reports_a_missing_rrd_folder(tmp_path, capsys):
    rc, out, err = _check(capsys, "--out", str(tmp_path), "--rerun-save", str(tmp_path / "no" / "x.rrd"))
    assert rc == EXIT_STARTUP and out == ""
    assert "sinks[1].path: folder" in err and str(tmp_path / "no") in err and len(err.strip().splitlines()) == 1


def test_check_reports_a_missing_output_folder(tmp_path, capsys):
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[[sinks]]\ntype = "files"\ndir = "{tmp_path / "frames"}"\n')
    rc, _, err = _check(capsys, "--config", str(cfg), "--out", str(tmp_path / "run"))
    assert rc == EXIT_STARTUP and "sinks[0].dir: output folder" in err
    (tmp_path / "frames").mkdir()
    assert _check(capsys, "--config", str(cfg), "--out", str(tmp_path / "run"))[0] == 0


def test_check_reports_an_out_that_is_a_file(tmp_path, capsys):
    (tmp_path / "f").write_text("")
    rc, _, err = _check(capsys, "--out", str(tmp_path / "f"))
    assert rc == EXIT_STARTUP and "service.out:" in err and "is not a folder" in err


@pytest.mark.parametrize(
    ("matcher", "bad", "good"),
    [("sgbm", 740, 736), ("census-sgm", 741, 740)],  # sgbm rounds 740 up to 752 (OpenCV's multiple of 16)
)
def test_check_reports_a_range_that_cannot_fit_the_default_scene(capsys, matcher, bad, good):
    """The embedded default plays Motorcycle (741 x 500): a range not below its width fails --check, naming both."""
    rc, out, err = _check(capsys, "--matcher", matcher, "--max-disparity", str(bad))
    assert rc == EXIT_STARTUP and out == ""
    assert err.startswith(f"vpp-service run: error: matcher.max_disparity: {bad} cannot fit the sim source's 741 x 500")
    assert "image width 741" in err and len(err.strip().splitlines()) == 1
    assert _check(capsys, "--matcher", matcher, "--max-disparity", str(good))[0] == 0


def test_check_knows_the_size_of_a_scaled_or_synthetic_scene(tmp_path, capsys):
    cfg = tmp_path / "c.toml"
    cfg.write_text('[source]\ntype = "sim"\nscale = 0.5\n')  # Motorcycle at 370 x 250
    rc, _, err = _check(capsys, "--config", str(cfg), "--max-disparity", "400")
    assert rc == EXIT_STARTUP and "cannot fit the sim source's 370 x 250 frames" in err
    assert _check(capsys, "--config", str(cfg), "--max-disparity", "352")[0] == 0
    cfg.write_text('[source]\ntype = "sim"\nscene = "synthetic"\nscene_options = {width = 100, height = 60}\n')
    rc, _, err = _check(capsys, "--config", str(cfg), "--max-disparity", "100")
    assert rc == EXIT_STARTUP and "cannot fit the sim source's 100 x 60 frames" in err
    assert _check(capsys, "--config", str(cfg), "--max-disparity", "64")[0] == 0


def _args(*argv: str):
    return build_parser().parse_args(["run", *argv])


def test_source_zenoh_blocks_instead_of_dropping():
    """A replay into the service loses nothing by default: --source zenoh picks the block input policy."""
    cfg = validate_config(overrides_from_args(DEFAULT_CONFIG, _args("--source", "zenoh")))
    assert cfg.queues.input_policy == "block"
    cfg = validate_config(overrides_from_args(DEFAULT_CONFIG, _args("--source", "zenoh", "--input-policy", "latest")))
    assert cfg.queues.input_policy == "latest"
    assert validate_config(overrides_from_args(DEFAULT_CONFIG, _args())).queues.input_policy == "latest"


def test_startup_and_closing_lines_say_where_things_are(tmp_path):
    args = _args("--source", "zenoh", "--out", str(tmp_path), "--zenoh-listen", "tcp/127.0.0.1:9")
    cfg = validate_config(overrides_from_args(DEFAULT_CONFIG, args))
    line = startup_line(cfg)
    assert "listen tcp/127.0.0.1:9" in line and "in vpp/rig0/in/*" in line and "out vpp/rig0/out/*" in line
    assert f"rerun ({tmp_path / 'vpp.rrd'})" in line and "status vpp/rig0/@status" in line
    end = closing_line(cfg, {"processed": 7})
    assert "after 7 frames" in end and str(tmp_path / "summary.json") in end and str(tmp_path / "vpp.rrd") in end


def test_check_reports_a_missing_sim_dataset_root(tmp_path, capsys):
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[source]\ntype = "sim"\nscene = "dataset"\nroot = "{tmp_path / "nope"}"\n')
    rc, _, err = _check(capsys, "--config", str(cfg))
    assert rc == EXIT_STARTUP and "source.root: no such folder" in err and str(tmp_path / "nope") in err


def _own_folder_without_gt(root: Path) -> Path:
    """A user's folder: the image pairs and a calibration, no ground truth, no sparse/ (yet)."""
    write_own_folder(root, own_scene(0.0625), forms=("png", "png"))
    shutil.rmtree(root / "sparse")
    return root


@pytest.mark.parametrize("source", ["files", "sim"])
def test_check_fails_for_a_folder_without_ground_truth_for_the_simulated_sensor(tmp_path, capsys, source):
    """The default sensor is simulated from ground truth: --check names the folder and what is missing."""
    root = _own_folder_without_gt(tmp_path / "mine")
    scene = 'scene = "dataset"\n' if source == "sim" else ""
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[source]\ntype = "{source}"\n{scene}root = "{root}"\n')
    rc, out, err = _check(capsys, "--config", str(cfg), "--out", str(tmp_path / "run"))
    assert rc == EXIT_STARTUP and out == "" and len(err.strip().splitlines()) == 1
    assert f"source.root: {root} has no ground truth (disp/) for the simulated sensor 'uniform'" in err
    assert 'source.sensor = "none"' in err and ("sparse/" in err)
    cfg.write_text(f'[source]\ntype = "{source}"\n{scene}root = "{root}"\nsensor = "none"\n')
    assert _check(capsys, "--config", str(cfg), "--out", str(tmp_path / "run"))[0] == 0


def test_check_passes_a_folder_with_its_own_sparse_depth(tmp_path, capsys):
    root = _own_folder_without_gt(tmp_path / "mine")
    (root / "sparse").mkdir()
    np.save(root / "sparse" / "000.npy", np.zeros((31, 46), np.float32))
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[source]\ntype = "files"\nroot = "{root}"\n')
    assert _check(capsys, "--config", str(cfg), "--out", str(tmp_path / "run"))[0] == 0
    (root / "left" / "001.png").unlink()  # a reader error is a --check error too
    rc, _, err = _check(capsys, "--config", str(cfg), "--out", str(tmp_path / "run"))
    assert rc == EXIT_STARTUP and "1 left images but 2 right images" in err


OWN_TOML = """[service]
out = "{out}"
[zenoh]
enabled = false
[source]
type = "files"
root = "{root}"
[matcher]
name = "sgbm"
[[sinks]]
type = "files"
dir = "{{out}}/frames"
create_dir = true
"""


def test_run_over_a_folder_with_its_own_sparse_depth_and_no_ground_truth(tmp_path):
    """Real data needs no ground truth: the user's points drive VPP; the summary has no accuracy figures."""
    frame = own_scene(0.25)
    write_own_folder(tmp_path / "mine", frame)
    (tmp_path / "mine" / "sparse" / "002.csv").write_text("u,v,d\n1,2,nan\n")  # one bad file: that frame only
    out = tmp_path / "run"
    cfg = tmp_path / "own.toml"
    cfg.write_text(OWN_TOML.format(out=out, root=tmp_path / "mine"))
    cmd = [*vpp_service_module_command(), "run", "--config", str(cfg), "--no-summary"]
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=120, check=False)
    assert proc.returncode == 0, proc.stderr
    counters = json.loads(proc.stdout)["counters"]
    assert counters["processed"] == 2 and counters["rejected"] == 1
    assert "rejected 1" in proc.stderr and "002.csv line 2: a non-finite number" in proc.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["metrics"]["bad2_answered_mean"] is None and summary["metrics"]["bad2_filled_mean"] is None
    assert sorted(p.name for p in (out / "frames").iterdir()) == [
        "rig0_000000_disparity.png",
        "rig0_000001_disparity.png",
    ]
    # scored here, against the ground truth the folder did not hold: the points were used (VPP beats SGBM alone)
    gt = frame.gt_disparity
    matcher = build_matcher("sgbm", {"max_disparity": int(np.ceil(np.nanmax(gt) / 16) * 16)})
    alone = compute_metrics(fuse(frame, matcher, None, depth=False).disparity, gt)["bad2"]
    for name in ("rig0_000000_disparity.png", "rig0_000001_disparity.png"):
        raw = cv2.imread(str(out / "frames" / name), cv2.IMREAD_UNCHANGED)
        disp = np.where(raw > 0, raw.astype(np.float32) / 256, np.nan)
        assert compute_metrics(disp, gt)["bad2"] < alone


RUN_BAG_TOML = """sinks = []
[service]
out = "{out}"
[zenoh]
enabled = false
[source]
type = "rosbag2"
path = "unused: --rosbag names the bag"
rate = 0.0
[matcher]
name = "bm"
[queues]
input_policy = "block"
output_policy = "block"
"""


def run_bag(tmp_path: Path, bag: Path) -> tuple[subprocess.CompletedProcess[str], Path]:
    """``vpp-service run --rosbag BAG --headless`` as a subprocess (zenoh off, replay as fast as possible)."""
    out = tmp_path / "run"
    cfg = tmp_path / "run.toml"
    cfg.write_text(RUN_BAG_TOML.format(out=out))
    cmd = [*vpp_service_module_command(), "run", "--config", str(cfg), "--rosbag", str(bag), "--headless"]
    return subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=120, check=False), out


@pytest.mark.parametrize(
    ("storage", "damage", "cause"), [("mcap", "cut", "bag.truncated"), ("sqlite3", "garbage", "bag.corrupt_row")]
)
def test_run_plays_a_damaged_bag_counts_the_damage_and_exits_0(tmp_path, storage, damage, cause):
    f = write_test_bag(tmp_path / "bag", storage)
    bad = cut(f, tmp_path / f"bad{f.suffix}", 0.9) if damage == "cut" else garble(f, tmp_path / f"bad{f.suffix}")
    proc, out = run_bag(tmp_path, bad)
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((out / "summary.json").read_text())
    n = summary["source"]["rejected_by"][cause]
    assert n >= 1 and set(summary["source"]["rejected_by"]) == {cause}
    assert 10 <= summary["counters"]["processed"] < 20
    closing = proc.stderr.strip().splitlines()[-1]
    assert f"stopped after {summary['counters']['processed']} frames; rejected {n} ({cause} {n})" in closing
    where = "ends at byte" if damage == "cut" else "unreadable"
    assert any(cause in line and str(bad) in line and where in line for line in proc.stderr.splitlines())


def test_run_on_a_bag_with_nothing_readable_fails_naming_the_file_and_the_cause(tmp_path):
    f = write_test_bag(tmp_path / "bag", "mcap")
    stub = cut(f, tmp_path / "stub.mcap", 4096 / f.stat().st_size)
    proc, _ = run_bag(tmp_path, stub)
    assert proc.returncode == 1
    assert "the source failed" in proc.stderr and "nothing readable" in proc.stderr and str(stub) in proc.stderr
    assert "bag.truncated" in proc.stderr


def test_run_stops_with_one_line_and_exit_2_on_a_frame_the_range_cannot_fit(tmp_path):
    """A bag's frame size is known only once its frames are read: the first 160-px frame stops a range of 160."""
    f = write_test_bag(tmp_path / "bag", "mcap")
    out = tmp_path / "run"
    cfg = tmp_path / "run.toml"
    cfg.write_text(RUN_BAG_TOML.format(out=out))
    cmd = [*vpp_service_module_command(), "run", "--config", str(cfg), "--rosbag", str(f), "--headless"]
    cmd += ["--max-disparity", "160"]
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=120, check=False)
    assert proc.returncode == EXIT_STARTUP, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert re.fullmatch(
        r"vpp-service run: stopped: frame seq=\d+ is 160 x 128: max_disparity must be > 0 and < the image width 160, "
        r'got 160; set a smaller matcher.max_disparity, or "auto"',
        lines[-1],
    ), lines[-1]
    assert not [line for line in lines if "rejected input" in line]  # one line, not a reject loop
    summary = json.loads((out / "summary.json").read_text())
    assert summary["counters"]["processed"] == 0 and summary["counters"]["rejected"] == 1
    assert summary["config_error"] in lines[-1]


def test_help_says_max_frames_counts_rejected_frames(capsys):
    with pytest.raises(SystemExit):
        main(["run", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--max-frames MAX_FRAMES stop after N frames processed or rejected" in text
