"""``vpp-service status``: one entry per rig on the service's own key; a clear message when nobody answers."""

from __future__ import annotations

import time

import cv2

from helpers.service_thread import service_in_thread
from helpers.zenoh_loopback import free_port, zenoh_test_config
from vpp_service.cli import EXIT_FAILURE, main


def _rig(name: str, out: str, listen: list[str], connect: list[str]) -> dict[str, object]:
    return {
        "service": {"rig": name, "out": out, "summary": False},
        "zenoh": {"mode": "client" if connect else "peer", "listen": listen, "connect": connect},
        "source": {"type": "sim", "scale": 0.25, "rate_hz": 2.0},
        "matcher": {"name": "bm", "max_disparity": 32},
        "sinks": [],
    }


def _wait_for(rigs: int, connect: str) -> dict[str, dict[str, object]]:
    from vpp_service.cli.status import query_status

    replies: dict[str, dict[str, object]] = {}
    deadline = time.monotonic() + 20
    while len(replies) < rigs and time.monotonic() < deadline:
        replies = query_status([connect], rig="*", timeout=1.0)
    return replies


def test_wildcard_status_lists_each_rig_under_its_own_key(tmp_path, capsys):
    """Two rigs behind a router (docs/deployment.md's layout: clients of one router) give two entries, not one."""
    import zenoh

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with (
        zenoh.open(zenoh_test_config(listen=[endpoint], mode="router")),
        service_in_thread(_rig("left", str(tmp_path / "a"), [], [endpoint])),
        service_in_thread(_rig("right", str(tmp_path / "b"), [], [endpoint])),
    ):
        replies = _wait_for(2, endpoint)
        assert sorted(replies) == ["vpp/left/@status", "vpp/right/@status"]
        assert replies["vpp/left/@status"]["rig"] == "left" and replies["vpp/right/@status"]["rig"] == "right"
        # what runs the matcher (the services run in this process: OpenCV's thread count is this one's)
        assert replies["vpp/left/@status"]["matcher"] == {
            "name": "bm",
            "engine": "opencv",
            "device": "cpu",
            "precision": "int16",
            "threads": cv2.getNumThreads(),
            "max_disparity": 32,
        }
        assert main(["status", "--rig", "*", "--connect", endpoint, "--timeout", "1"]) == 0
        assert '"vpp/left/@status"' in capsys.readouterr().out


def test_status_says_when_no_service_answered(capsys):
    import zenoh

    from helpers.zenoh_loopback import zenoh_test_config

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with zenoh.open(zenoh_test_config(listen=[endpoint])):  # reachable, but no service there
        assert main(["status", "--connect", endpoint, "--timeout", "0.5"]) == EXIT_FAILURE
    captured = capsys.readouterr()
    assert captured.out == ""
    assert "no service answered on vpp/*/@status" in captured.err and endpoint in captured.err


def test_status_to_a_closed_port_says_it_could_not_connect(capsys):
    endpoint = f"tcp/127.0.0.1:{free_port()}"  # nothing listens there
    assert main(["status", "--connect", endpoint, "--timeout", "1"]) == EXIT_FAILURE
    captured = capsys.readouterr()
    assert captured.out == ""
    assert f"could not connect to {endpoint}" in captured.err and "within" not in captured.err
