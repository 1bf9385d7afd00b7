"""build_pipeline asks the plugins (needs_depth) instead of reading their options."""

from __future__ import annotations

import copy
import io
import json
import logging
import os
import stat
import subprocess
import threading
import time
from pathlib import Path

import pytest
import zenoh

from helpers.cli import vpp_service_module_command
from helpers.toml import toml_dumps
from helpers.zenoh_loopback import collect, free_port, zenoh_test_config
from vpp_service.cli import build_parser
from vpp_service.cli.run import startup_line
from vpp_service.service.app import build_pipeline, run_service, zenoh_log_level
from vpp_service.service.config import DEFAULT_CONFIG, validate_config
from vpp_service.sources.base import SOURCES, Source
from vpp_service.sources.sim import SimSource, SimSourceOptions

ROOT = Path(__file__).resolve().parents[1]


def config(sinks: list[dict]) -> dict:
    data = copy.deepcopy(DEFAULT_CONFIG)
    data["sinks"] = sinks
    return data


def built_pipeline(tmp_path, sinks: list[dict]):
    """The pipeline of ``config(sinks)``, built, not opened (a files sink's ``dir`` put under ``tmp_path``)."""
    for s in sinks:
        if "dir" in s:
            s["dir"] = str(tmp_path / s["dir"])
    return build_pipeline(validate_config(config(sinks)), session=None)


@pytest.mark.parametrize(
    ("sinks", "depth"),
    [
        ([], False),
        ([{"type": "zenoh", "outputs": ["disparity"]}], False),
        ([{"type": "zenoh", "outputs": ["disparity", "depth"]}], True),
        ([{"type": "zenoh", "outputs": ["disparity"]}, {"type": "record", "dir": "REC"}], False),
        ([{"type": "zenoh", "outputs": ["disparity"]}, {"type": "files", "dir": "F", "depth": True}], True),
        ([{"type": "rerun", "path": "x.rrd"}], True),
    ],
)
def test_metric_depth_only_when_a_sink_reads_it(tmp_path, sinks, depth):
    pipe = built_pipeline(tmp_path, sinks)
    assert pipe.process.depth is depth
    assert [type(s).__name__ for s in pipe.sinks] == [f"{s['type'].capitalize()}Sink" for s in sinks]


# ------------------------------------------------------------ runtime failures (issue: a dead source, full disk)
class DyingSource(Source):
    """A source whose thread dies on an unexpected error after two frames."""

    Options = SimSourceOptions

    def run(self, emit, reject):
        sim = SimSource(self.options, self.context)
        sim.open()
        for seq in range(2):
            emit(sim.frame(seq))
        raise RuntimeError("camera driver crashed")


def small_config(tmp_path, **service) -> dict:
    data = config([])
    data["zenoh"] = {"enabled": False}
    data["source"] = {
        "type": "sim",
        "scene": "synthetic",
        "scene_options": {"height": 48, "width": 96, "max_disparity": 16},
        "count": 3,
    }
    data["matcher"] = {"name": "bm", "max_disparity": 16}
    data["service"] = {"out": str(tmp_path / "out"), "summary": False, **service}
    return data


@pytest.fixture
def dying_source(monkeypatch):
    monkeypatch.setitem(SOURCES._items, "dies", DyingSource)


def test_dead_source_is_a_failure_not_a_clean_exit(tmp_path, dying_source):
    data = small_config(tmp_path)
    data["source"]["type"] = "dies"
    data["source"].pop("count")
    summary = run_service(validate_config(data), stream=None)
    assert summary["counters"]["processed"] == 2
    assert "camera driver crashed" in summary["source_error"]
    written = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert "camera driver crashed" in written["source_error"]
    # the CLI turns it into exit code 1 (systemd restarts the service)
    cfg = tmp_path / "dies.toml"
    cfg.write_text(toml_dumps(data))
    # (a second run into the same out: the restarted service replaces its own outputs)
    args = build_parser().parse_args(["run", "--config", str(cfg), "--no-summary", "--overwrite"])
    assert args.func(args) == 1


def test_start_line_and_summary_name_the_engine_device_and_precision(tmp_path):
    from vpp_service.matchers import census_sgm

    data = small_config(tmp_path)
    data["matcher"] = {"name": "census-sgm", "max_disparity": 32, "threads": 2}
    cfg = validate_config(data)
    stream = io.StringIO()
    summary = run_service(cfg, stream=stream, banner=lambda matcher: startup_line(cfg, matcher))
    engine = "cython" if census_sgm._k is census_sgm.portable else "cython-avx2"
    assert summary["matcher"] == {
        "name": "census-sgm",
        "engine": engine,
        "device": "cpu",
        "precision": "int16",
        "threads": 2,
        "max_disparity": 32,
    }
    assert f"| matcher census-sgm ({engine} cpu int16, 2 threads) |" in stream.getvalue().splitlines()[0]
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["matcher"] == summary["matcher"]


def test_healthy_run_exits_0(tmp_path):
    cfg = tmp_path / "ok.toml"
    cfg.write_text(toml_dumps(small_config(tmp_path)))
    args = build_parser().parse_args(["run", "--config", str(cfg), "--no-summary"])
    assert args.func(args) == 0


@pytest.mark.parametrize(
    ("sinks", "confidence"),
    [
        ([{"type": "zenoh", "outputs": ["disparity", "depth"]}], False),
        ([{"type": "zenoh", "outputs": ["disparity"], "on_request": ["confidence"]}], True),
        ([{"type": "ros2", "outputs": ["disparity", "confidence"]}], True),
        ([{"type": "files", "dir": "F", "depth": True}], False),
        ([{"type": "files", "dir": "F", "confidence": True}], True),
        ([{"type": "rerun", "path": "x.rrd"}], False),
        ([{"type": "rerun", "path": "x.rrd", "confidence": True}], True),
    ],
)
def test_confidence_only_when_a_sink_reads_it(tmp_path, sinks, confidence):
    pipe = built_pipeline(tmp_path, sinks)
    assert pipe.process.confidence is confidence


def test_a_run_writes_the_confidence_and_min_confidence_makes_holes(tmp_path):
    """census-sgm with min_confidence 0.5 and the files sink's confidence: every answered pixel has >= 0.5."""
    import numpy as np

    data = small_config(tmp_path)
    data["matcher"] = {"name": "census-sgm", "max_disparity": 16, "min_confidence": 0.5}
    data["sinks"] = [
        {"type": "files", "dir": str(tmp_path / "F"), "create_dir": True, "formats": ["npy"], "confidence": True}
    ]
    cfg = tmp_path / "conf.toml"
    cfg.write_text(toml_dumps(data))
    args = build_parser().parse_args(["run", "--config", str(cfg), "--no-summary"])
    assert args.func(args) == 0
    confs = sorted((tmp_path / "F").glob("*_confidence.npy"))
    assert len(confs) == 3 and len(list((tmp_path / "F").glob("*_confidence.png"))) == 3
    for path in confs:
        conf = np.load(path)
        disp = np.load(str(path).replace("_confidence.npy", "_disparity.npy"))
        assert conf.shape == disp.shape and np.isfinite(disp).any()
        assert np.all(conf[np.isfinite(disp)] >= 0.5) and np.all(conf[np.isnan(disp)] == 0)


def test_summary_write_failure_is_counted_not_fatal(tmp_path):
    """summary.json cannot be written (its name is taken by a non-empty folder): counted, logged, run ends."""
    out = tmp_path / "out"
    (out / "summary.json" / "x").mkdir(parents=True)
    summary = run_service(validate_config(small_config(tmp_path, summary_period_s=0.05)), stream=None)
    assert summary["counters"]["processed"] == 3
    assert summary["summary_write_errors"] >= 1
    assert (out / "summary.json").is_dir()
    assert not [p for p in out.iterdir() if p.name.startswith(".")]  # no temporary file left


def test_summary_json_gets_the_umask_mode(tmp_path, umask):
    run_service(validate_config(small_config(tmp_path)), stream=None)
    assert stat.S_IMODE((tmp_path / "out" / "summary.json").stat().st_mode) == 0o666 & ~umask


@pytest.mark.parametrize("mode", ["peer", "client"])
def test_starts_with_the_router_down_and_connects_when_it_appears(tmp_path, zenoh_endpoint, mode):
    """Pointed at a router that is not up yet, the service waits for it, then outputs flow once it appears.

    Peer mode runs at once and connects in the background; client mode retries opening its session.
    """
    data = small_config(tmp_path)
    data["source"].update(count=0, rate_hz=20.0)
    data["zenoh"] = {"mode": mode, "listen": [], "connect": [zenoh_endpoint]}
    data["sinks"] = [{"type": "zenoh", "outputs": ["disparity"]}]
    data["service"]["rig"] = "rd"
    stop = threading.Event()
    result = {}
    runner = threading.Thread(target=lambda: result.update(run_service(validate_config(data), stop, None)))
    runner.start()
    try:
        time.sleep(1.0)
        assert runner.is_alive(), "the service did not survive the missing router"
        with (
            zenoh.open(zenoh_test_config(listen=[zenoh_endpoint], mode="router")),
            zenoh.open(zenoh_test_config(connect=[zenoh_endpoint], mode="client")) as viewer,
        ):
            sub = viewer.declare_subscriber("vpp/rd/out/disparity", zenoh.handlers.FifoChannel(64))
            t0 = time.monotonic()
            assert collect(sub, 1, timeout=8.0), "no output after the router appeared"
            assert time.monotonic() - t0 < 8.0
            replies = list(viewer.get("vpp/rd/@status", timeout=5.0))
            status = json.loads(replies[0].ok.payload.to_string())
            assert status["zenoh"]["routers"] == 1
    finally:
        stop.set()
        runner.join(20)
    assert not runner.is_alive() and result["counters"]["published"] > 0


def test_stop_while_waiting_for_the_router(tmp_path, zenoh_endpoint):
    """A client whose router never appears still stops promptly on request (nothing ran)."""
    data = small_config(tmp_path)
    data["zenoh"] = {"mode": "client", "listen": [], "connect": [zenoh_endpoint]}
    stop = threading.Event()
    threading.Timer(0.5, stop.set).start()
    t0 = time.monotonic()
    summary = run_service(validate_config(data), stop, None)
    assert time.monotonic() - t0 < 5.0
    assert summary["counters"]["processed"] == 0 and summary["zenoh"] == {"routers": 0, "peers": 0}


def test_summary_lines_in_a_log_only_when_something_changed(tmp_path):
    """Not a terminal (a journal, a file): an idle service does not repeat its summary every period."""
    import io
    import threading

    from helpers.zenoh_loopback import free_port
    from vpp_service.service.app import run_service

    data = {
        "service": {"out": str(tmp_path), "summary_period_s": 0.05},
        "zenoh": {"listen": [f"tcp/127.0.0.1:{free_port()}"]},
        "source": {"type": "zenoh"},  # nobody publishes: idle
        "matcher": {"name": "bm", "max_disparity": 32},
        "sinks": [],
    }
    stream, stop = io.StringIO(), threading.Event()

    def stop_later() -> None:  # 1.5 s (~30 summary periods) after the service has started
        while "started" not in stream.getvalue() and not stop.wait(0.05):
            pass
        stop.wait(1.5)
        stop.set()

    threading.Thread(target=stop_later, daemon=True).start()
    run_service(validate_config(data), stop, stream, banner="started")
    lines = stream.getvalue().splitlines()
    assert lines[0] == "started"
    assert len(lines) == 3, lines  # banner, one periodic line (first report), the final line; ~30 periods passed
    assert lines[1] == "waiting for frames on vpp/rig0/in/frame: nothing has arrived yet"  # says what it waits on
    assert lines[2].startswith("0.0 fps") and "recv 0" in lines[2]  # the final line: the counters


def test_session_drops_messages_over_its_max_message_size(zenoh_endpoint):
    import zenoh

    from helpers.zenoh_loopback import zenoh_test_config
    from vpp_service.service.app import zenoh_config
    from vpp_service.service.config import ZenohSection

    section = ZenohSection(listen=[zenoh_endpoint], max_message_mb=1.0)
    conf = zenoh_config(section)
    assert json.loads(conf.get_json("transport/link/rx/max_message_size")) == (1 << 20) + 64 * 1024
    got: list[int] = []
    with zenoh.open(conf) as svc, zenoh.open(zenoh_test_config(connect=[zenoh_endpoint])) as peer:
        svc.declare_subscriber("t/x", lambda s: got.append(len(s.payload)))
        time.sleep(0.5)
        pub = peer.declare_publisher("t/x", congestion_control=zenoh.CongestionControl.BLOCK)
        pub.put(bytes(4 << 20))  # over the cap: Zenoh never assembles it
        pub.put(bytes(1000))  # the link survives: the next message arrives
        deadline = time.monotonic() + 5
        while not got and time.monotonic() < deadline:
            time.sleep(0.01)
        time.sleep(0.2)
    assert got == [1000]


def test_max_message_mb_is_validated():
    from vpp_service.service.config import ZenohSection

    with pytest.raises(ValueError, match="max_message_mb"):
        ZenohSection(max_message_mb=0)


@pytest.fixture
def recorded_frames(tmp_path):
    """Nine valid wire-format frames in a folder (a recording to replay)."""
    from vpp_service.sources.base import SourceContext, build_source
    from vpp_service.transport import wire

    folder = tmp_path / "rec"
    folder.mkdir()
    scene = {"height": 120, "width": 240, "max_disparity": 32}
    src = build_source("sim", {"scene": "synthetic", "scene_options": scene, "rate_hz": 0}, SourceContext())
    src.open()
    for i in range(9):
        (folder / f"{i:03d}.msgpack").write_bytes(wire.encode_frame(src.frame(i)))
    return folder


def replay_config(tmp_path, folder, queues: dict | None = None) -> dict:
    data = small_config(tmp_path)
    data["source"] = {"type": "files", "root": str(folder), "format": "msgpack"}  # rate_hz 0: as fast as it reads
    data["matcher"] = {"name": "census-sgm", "max_disparity": 32}
    data["sinks"] = [{"type": "rerun", "mode": "save", "path": str(tmp_path / "x.rrd"), "queue_size": 1}]
    if queues is not None:
        data["queues"] = queues
    return data


def test_a_finite_source_loses_no_frame_by_default(tmp_path, recorded_frames):
    cfg = validate_config(replay_config(tmp_path, recorded_frames))
    assert (cfg.queues.input_policy, cfg.queues.output_policy) == ("block", "block")
    summary = run_service(cfg, stream=None)
    c = summary["counters"]
    assert c["processed"] == 9 and c["dropped"] == 0 and c["rejected"] == 0, summary["dropped"]
    (rerun,) = summary["sinks"].values()
    assert rerun["written"] == 9 and rerun["dropped"] == 0, summary["sinks"]


def test_a_replay_asked_to_drop_counts_every_drop_by_cause(tmp_path, recorded_frames):
    cfg = validate_config(replay_config(tmp_path, recorded_frames, {"input_policy": "latest", "input_size": 1}))
    assert (cfg.queues.input_policy, cfg.queues.output_policy) == ("latest", "block")  # only what was asked
    summary = run_service(cfg, stream=None)
    c, d = summary["counters"], summary["dropped"]
    assert c["processed"] + d["input_queue"] == 9 and c["dropped"] == sum(d.values()) == d["input_queue"]


def test_closing_line_says_what_was_dropped_by_cause(tmp_path):
    from vpp_service.cli.run import closing_line

    cfg = validate_config(small_config(tmp_path))
    line = closing_line(cfg, {"processed": 1, "dropped": 0})
    assert "after 1 frame;" in line and "dropped" not in line
    line = closing_line(cfg, {"processed": 3, "dropped": 6}, {"input_queue": 6, "shutdown": 0})
    assert "after 3 frames; dropped 6 frames (input_queue 6);" in line


def test_run_never_silently_replaces_a_previous_run(tmp_path, capsys):
    from vpp_service.cli import EXIT_STARTUP, main

    data = small_config(tmp_path)
    data["sinks"] = [{"type": "rerun", "mode": "save", "path": "{out}/vpp.rrd"}]
    cfg = tmp_path / "run.toml"
    cfg.write_text(toml_dumps(data))
    assert main(["run", "--config", str(cfg), "--no-summary"]) == 0
    out = tmp_path / "out"
    before = {p.name: p.stat().st_mtime_ns for p in out.iterdir()}
    assert set(before) == {"summary.json", "vpp.rrd"}
    assert main(["run", "--config", str(cfg), "--no-summary"]) == EXIT_STARTUP
    err = capsys.readouterr().err
    assert "holds a previous run's outputs" in err and "summary.json" in err and "vpp.rrd" in err
    assert "--overwrite" in err
    assert {p.name: p.stat().st_mtime_ns for p in out.iterdir()} == before  # untouched
    assert main(["run", "--config", str(cfg), "--no-summary", "--overwrite"]) == 0
    assert (out / "summary.json").stat().st_mtime_ns > before["summary.json"]


def test_a_failed_start_leaves_no_run_folder(tmp_path, zenoh_endpoint):
    import zenoh as z

    from vpp_service.cli import EXIT_STARTUP, main

    data = small_config(tmp_path)
    data["zenoh"] = {"listen": [zenoh_endpoint]}
    cfg = tmp_path / "run.toml"
    cfg.write_text(toml_dumps(data))
    with z.open(zenoh_test_config(listen=[zenoh_endpoint])):  # the port is taken: the service cannot open
        assert main(["run", "--config", str(cfg), "--no-summary"]) == EXIT_STARTUP
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    ("level", "rust_log", "want"),
    [(logging.WARNING, None, None), (logging.INFO, None, "info"), (logging.DEBUG, "", "debug"), (30, "warn", "env")],
)
def test_zenoh_log_follows_our_verbosity(level, rust_log, want):
    assert zenoh_log_level(level, rust_log) == want


@pytest.mark.parametrize("verbose", [False, True])
def test_a_clean_run_prints_no_raw_zenoh_line_unless_asked(tmp_path, verbose):
    """Zenoh writes its own log raw on stdout: off on a clean run (stdout is the JSON line), on with -v."""
    port = free_port()
    cfg = tmp_path / "c.toml"
    cfg.write_text(
        f'[service]\nout = "{tmp_path / "run"}"\nsummary = false\n'
        f'[zenoh]\nlisten = ["tcp/127.0.0.1:{port}"]\n'
        '[source]\ntype = "sim"\nscale = 0.25\nrate_hz = 0.0\n'
        '[[sinks]]\ntype = "zenoh"\n'
    )
    env = {k: v for k, v in os.environ.items() if k != "RUST_LOG"}
    cmd = [*vpp_service_module_command(), *(["-v"] if verbose else []), "run", "--config", str(cfg)]
    proc = subprocess.run(
        [*cmd, "--max-frames", "2"], cwd=ROOT, env=env, capture_output=True, text=True, timeout=120, check=False
    )
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert json.loads(lines[-1])["counters"]["processed"] == 2
    zenoh_lines = [line for line in lines[:-1] if "zenoh" in line]
    if verbose:  # Zenoh's INFO, as our -v asks
        assert any(f"Zenoh can be reached at: tcp/127.0.0.1:{port}" in line for line in zenoh_lines), proc.stdout
    else:
        assert lines == lines[-1:], proc.stdout
