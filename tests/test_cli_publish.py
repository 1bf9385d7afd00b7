"""``vpp-service publish``: meets ``run`` on the shared default endpoint; says so when nobody subscribes.

``publish --rosbag`` of a damaged bag sends every readable message and counts the damage.
"""

from __future__ import annotations

import json
import signal
import time
from collections.abc import Iterator

import pytest
import zenoh

from helpers.damaged_bags import cut, write_test_bag
from helpers.ros2_robot import key
from helpers.service_thread import service_in_thread
from helpers.zenoh_loopback import collect, free_port, zenoh_test_config
from vpp_service.cli import EXIT_FAILURE, EXIT_STARTUP, main
from vpp_service.cli.status import query_status
from vpp_service.service.config import ENDPOINT_ENV
from vpp_service.transport.ros2.bag import read_bag
from vpp_service.transport.ros2.bag_damage import ignore_damage


@pytest.fixture
def shared_endpoint(monkeypatch: pytest.MonkeyPatch) -> str:
    """A free loopback port as every command's default endpoint (what ``$VPP_SERVICE_ENDPOINT`` sets)."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    monkeypatch.setenv(ENDPOINT_ENV, endpoint)
    return endpoint


@pytest.fixture
def keep_signal_handlers() -> Iterator[None]:
    """``publish`` installs SIGINT/SIGTERM handlers; put pytest's back afterwards."""
    handlers = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    yield
    for s, h in handlers.items():
        signal.signal(s, h)


def test_publish_run_and_status_meet_on_the_default_endpoint(tmp_path, shared_endpoint, keep_signal_handlers, capsys):
    """No endpoint flag anywhere: run listens where publish and status connect, and the frames are processed."""
    data = {
        "service": {"out": str(tmp_path / "run"), "max_frames": 3, "summary": False},
        "source": {"type": "zenoh"},
        "matcher": {"name": "bm", "max_disparity": 32},
        "queues": {"input_policy": "block"},  # what `run --source zenoh` chooses
        "sinks": [],
    }
    with service_in_thread(data) as (thread, result):
        deadline = time.monotonic() + 30  # the service is up once it answers @status on the default endpoint
        while not query_status([shared_endpoint], rig="rig0", timeout=1.0) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert main(["status", "--rig", "rig0", "--timeout", "10"]) == 0
        assert '"vpp/rig0/@status"' in capsys.readouterr().out
        rc = main(["publish", "--scale", "0.25", "--count", "3", "--rate", "5", "--wait-subscriber", "10"])
        assert rc == 0
        thread.join(30)
        assert not thread.is_alive()
    assert result["status"]["counters"]["processed"] == 3  # max_frames reached: every frame arrived


def test_publish_without_subscriber_exits_1_with_a_message(shared_endpoint, keep_signal_handlers, capsys):
    t0 = time.monotonic()
    assert main(["publish", "--scale", "0.25", "--count", "1", "--wait-subscriber", "0.5"]) == EXIT_FAILURE
    assert time.monotonic() - t0 < 10
    captured = capsys.readouterr()
    assert f"could not connect to {shared_endpoint}" in captured.err  # nothing listens there
    assert '"sent"' not in captured.out


def test_publish_with_a_peer_but_no_subscriber_exits_1_with_a_message(shared_endpoint, keep_signal_handlers, capsys):
    import zenoh

    from helpers.zenoh_loopback import zenoh_test_config

    with zenoh.open(zenoh_test_config(listen=[shared_endpoint])):  # reachable, but nobody subscribes
        assert main(["publish", "--scale", "0.25", "--count", "1", "--wait-subscriber", "0.5"]) == EXIT_FAILURE
    captured = capsys.readouterr()
    assert "no subscriber on vpp/rig0/in/frame" in captured.err and shared_endpoint in captured.err
    assert "--send-anyway" in captured.err and '"sent"' not in captured.out


def test_publish_send_anyway_sends_without_subscriber(shared_endpoint, keep_signal_handlers, capsys):
    rc = main(
        ["publish", "--scale", "0.25", "--count", "1", "--rate", "0", "--wait-subscriber", "0.2", "--send-anyway"]
    )
    assert rc == 0
    out = capsys.readouterr().out
    assert '"sent": 1' in out and '"confirmed": false' in out  # no service answered the delivery check


def test_publish_rejects_a_negative_confirm_timeout(capsys):
    assert main(["publish", "--count", "1", "--confirm-timeout", "-1"]) == EXIT_STARTUP
    assert "--confirm-timeout: must be >= 0" in capsys.readouterr().err


def test_a_replay_into_the_service_loses_nothing(tmp_path, shared_endpoint, keep_signal_handlers, capsys):
    """``publish`` as fast as it can into ``run --source zenoh``'s default (block): every frame is processed.

    Fails when publish closes its session with frames still queued (before its @status delivery check).
    """
    data = {
        "service": {"out": str(tmp_path / "run"), "max_frames": 12, "summary": False},
        "source": {"type": "zenoh", "ring_size": 2},
        "matcher": {"name": "sgbm", "max_disparity": 32},
        "queues": {"input_policy": "block", "input_size": 2},  # what `run --source zenoh` chooses
        "sinks": [],
    }
    with service_in_thread(data) as (thread, result):
        rc = main(["publish", "--scale", "0.5", "--count", "12", "--rate", "0", "--wait-subscriber", "30"])
        assert rc == 0
        assert '"confirmed": true' in capsys.readouterr().out
        thread.join(60)
        assert not thread.is_alive()  # with the latest policy frames are dropped and max_frames is never reached
    status = result["status"]
    assert status["counters"]["processed"] == 12 and status["counters"]["dropped"] == 0, status["dropped"]


@pytest.fixture
def middlebury2006_folder(tmp_path):
    """A Middlebury 2005/2006-layout folder (no calibration file, as those sets ship) of two synthetic scenes."""
    import cv2
    import numpy as np

    from vpp_service.sources.synthetic import make_scene

    root = tmp_path / "midd"
    for k in range(2):
        frame = make_scene(height=96, width=160, max_disparity=24, seed=k)
        scene = root / f"Scene{k}"
        scene.mkdir(parents=True)
        cv2.imwrite(str(scene / "view1.png"), frame.left)
        cv2.imwrite(str(scene / "view5.png"), frame.right)
        cv2.imwrite(str(scene / "disp1.png"), np.round(frame.gt_disparity * 3).astype(np.uint8))  # value / 3
    return root


def test_publish_plays_a_calibration_less_middlebury_folder_into_run(
    tmp_path, middlebury2006_folder, shared_endpoint, keep_signal_handlers, capsys
):
    """--root alone (dataset auto) with nominal f / baseline: every frame reaches the service, none rejected."""
    data = {
        "service": {"out": str(tmp_path / "run"), "max_frames": 2, "summary": False},
        "source": {"type": "zenoh"},
        "matcher": {"name": "bm", "max_disparity": 32},
        "queues": {"input_policy": "block"},
        "sinks": [],
    }
    with service_in_thread(data) as (thread, result):
        rc = main(["publish", "--root", str(middlebury2006_folder), "--rate", "0", "--wait-subscriber", "30"])
        captured = capsys.readouterr()
        assert rc == 0, captured.err
        assert '"sent": 2' in captured.out  # (the service stops at max_frames: it may be gone before confirming)
        thread.join(60)
        assert not thread.is_alive()
    c = result["status"]["counters"]
    assert c["processed"] == 2 and c["rejected"] == 0 and c["no_depth"] == 0, result["status"]


def test_publish_recording_and_root_together_is_an_error(tmp_path, capsys):
    assert main(["publish", "--recording", str(tmp_path), "--root", str(tmp_path)]) == EXIT_STARTUP
    assert "--recording and --dataset/--root" in capsys.readouterr().err


@pytest.mark.parametrize("value", ["0", "-1", "nan"])
def test_publish_rejects_a_bad_nominal_calibration(value, capsys):
    assert main(["publish", "--count", "1", "--nominal-f", value]) == EXIT_STARTUP
    assert "--nominal-f: must be a finite number > 0" in capsys.readouterr().err


def test_publish_always_exits_cleanly(tmp_path, middlebury2006_folder, shared_endpoint):
    """Ten publish processes run to completion (sending, or failing for want of a subscriber): never an abort."""
    import subprocess
    import sys

    cmd = [sys.executable, "-m", "vpp_service", "publish", "--root", str(middlebury2006_folder), "--rate", "0"]
    rcs = []
    for k in range(10):
        flags = ["--wait-subscriber", "0.2"] + (["--send-anyway"] if k % 2 else [])
        proc = subprocess.run([*cmd, *flags], capture_output=True, text=True, timeout=120, check=False)
        rcs.append(proc.returncode)
        assert "terminate called" not in proc.stderr, proc.stderr
    assert rcs == [EXIT_FAILURE, 0] * 5  # no subscriber: exit 1 with a message; --send-anyway: sent, exit 0


@pytest.mark.parametrize(("storage", "fraction"), [("mcap", 0.5), ("sqlite3", 0.9)])
def test_publish_rosbag_plays_a_cut_bag_up_to_the_cut_and_counts_it(
    tmp_path, storage, fraction, keep_signal_handlers, capsys
):
    """Every readable message goes out (the camera_info payloads, bit for bit); the damage is named and counted."""
    f = write_test_bag(tmp_path / "bag", storage)
    bad = cut(f, tmp_path / f"cut{f.suffix}", fraction)
    readable = list(read_bag(bad, on_damage=ignore_damage))
    infos = [m.data for m in readable if m.topic == "/stereo/left/camera_info"]
    assert 0 < len(readable) < 100 and infos
    ep = f"tcp/127.0.0.1:{free_port()}"
    with zenoh.open(zenoh_test_config(listen=[ep])) as s:
        sub = s.declare_subscriber(
            key(0, "/stereo/left/camera_info", "sensor_msgs/msg/CameraInfo"), zenoh.handlers.FifoChannel(64)
        )
        rc = main(["publish", "--rosbag", str(bad), "--rosbag-rate", "0", "--connect", ep])
        got = collect(sub, len(infos))
    assert rc == 0
    assert [smp.payload.to_bytes() for smp in got] == infos
    out, err = capsys.readouterr()
    line = json.loads(out.strip().splitlines()[-1])
    causes = line_causes(err)
    assert line["sent"] == len(readable) and causes and line["damaged"] == {"bag.truncated": len(causes)}
    assert all(str(bad) in c for c in causes)


def line_causes(err: str) -> list[str]:
    return [ln for ln in err.splitlines() if ln.startswith("vpp-service publish: damaged bag: bag.truncated")]


def test_publish_calib_plays_a_raw_folder_into_a_rectifying_service(
    tmp_path, shared_endpoint, keep_signal_handlers, capsys
):
    """--calib: raw frames go without calib or depth; the service's [rectify] answers as on the rectified scene."""
    from helpers.raw_rig import write_raw_scene
    from helpers.shared_data import need_shared
    from vpp_service.datasets import open_dataset
    from vpp_service.fusion import fuse
    from vpp_service.matchers import build_matcher

    root = need_shared("middlebury2005_2006_thirdsize")
    raw_root, lp, rp = write_raw_scene(tmp_path, root, "Books")
    reference = fuse(
        open_dataset("middlebury2006", root).select(["Books"])[0], build_matcher("sgbm", {"max_disparity": 96})
    )
    data = {
        "service": {"out": str(tmp_path / "run"), "max_frames": 1, "summary": False},
        "source": {"type": "zenoh"},
        "vpp": {"enabled": False},
        "matcher": {"name": "sgbm", "max_disparity": 96},
        "queues": {"input_policy": "block"},
        "rectify": {"left": str(lp), "right": str(rp)},
        "sinks": [],
    }
    with service_in_thread(data) as (thread, result):
        argv = [
            "publish",
            "--root",
            str(raw_root),
            "--calib",
            str(lp),
            str(rp),
            "--rate",
            "0",
            "--wait-subscriber",
            "30",
        ]
        rc = main(argv)
        captured = capsys.readouterr()
        assert rc == 0, captured.err
        thread.join(60)
        assert not thread.is_alive()
    status = result["status"]
    assert status["counters"]["processed"] == 1 and status["counters"]["rejected"] == 0, status
    bad2 = status["metrics"]["last"]["bad2_answered"]
    assert bad2 <= reference.metrics["bad2_answered"] + 2.0


def test_publish_rejects_a_bad_calib(tmp_path, capsys):
    from helpers.raw_rig import write_rig_yamls

    lp, rp = write_rig_yamls(tmp_path, 64, 48)
    rp.write_text(rp.read_text().replace("projection_matrix:", "projection_matrix_:"))  # monocular: P = [K | 0]
    assert main(["publish", "--count", "1", "--calib", str(lp), str(rp)]) == EXIT_STARTUP
    err = capsys.readouterr().err
    assert err.startswith("vpp-service publish: error: --calib: ") and "not a rectified pair: P fx' differs" in err
