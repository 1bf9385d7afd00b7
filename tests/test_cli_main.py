"""The ``vpp-service`` command itself: --version, -v anywhere, exit statuses, help text."""

from __future__ import annotations

import argparse
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from helpers.zenoh_loopback import free_port, zenoh_test_config
from vpp_service import __version__
from vpp_service.cli import COMMANDS, EXIT_STARTUP, build_parser, main

ROOT = Path(__file__).resolve().parents[1]


def _cli(*args: str, timeout: float = 60) -> subprocess.CompletedProcess[str]:
    """``python -m vpp_service ARGS`` on this checkout's code."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run(
        [sys.executable, "-m", "vpp_service", *args],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )


def test_version(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"vpp-service {__version__}"


def test_verbose_counts():
    parser = build_parser()
    assert parser.parse_args(["status"]).verbose == 0
    assert parser.parse_args(["-v", "status"]).verbose == 1
    assert parser.parse_args(["status", "-v"]).verbose == 1
    assert parser.parse_args(["status", "-vv"]).verbose == 2


def test_a_zenoh_startup_error_is_one_line_and_exit_2(tmp_path):
    """A second service on a port already in use: one line on stderr, exit 2 (no traceback)."""
    import zenoh

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with zenoh.open(zenoh_test_config(listen=[endpoint])):
        proc = _cli("run", "--zenoh-listen", endpoint, "--max-frames", "1", "--out", str(tmp_path), "--no-summary")
    assert proc.returncode == EXIT_STARTUP, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert lines[0].startswith("vpp-service run: error: zenoh:") and "Address already in use" in lines[0]
    assert ".rs:" not in lines[0]  # Zenoh's Rust source locations are stripped


def test_a_config_error_is_one_line_and_exit_2(capsys):
    assert main(["run", "--max-frames", "-1", "--check"]) == EXIT_STARTUP
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["vpp-service run: error: service.max_frames: got -1; expected >= 0"]


def _sub_parsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


_REST = re.compile(r"``|:[a-z]+:`")


@pytest.mark.parametrize("command", COMMANDS)
def test_help_is_plain_text_with_help_on_every_flag(command):
    sub = _sub_parsers(build_parser())
    if command not in sub:
        pytest.skip(f"{command} is not built into this install")
    parser = sub[command]
    text = parser.format_help()
    assert not _REST.search(text), text
    for action in parser._actions:
        if action.option_strings:
            assert action.help, f"{command} {action.option_strings[0]} has no help"


def test_help_shows_defaults():
    text = " ".join(_sub_parsers(build_parser())["publish"].format_help().split())
    assert "(default: 10.0)" in text and "(default: rig0)" in text


def test_top_level_help_states_the_exit_statuses():
    text = build_parser().format_help()
    assert "exit status" in text and f"{EXIT_STARTUP} configuration or start-up error" in text


def test_a_multi_line_error_is_shown_whole(tmp_path, capsys):
    (tmp_path / "not-a-scene").mkdir()
    assert main(["eval", "--root", str(tmp_path), "--methods", "baseline"]) == EXIT_STARTUP
    err = capsys.readouterr().err
    assert "no known dataset layout" in err and "looked for:" in err
    assert "middlebury2006: <scene>/view1.png" in err and "kitti2012:" in err  # the list after the first line


def test_help_and_code_agree_on_ctrl_c(tmp_path):
    """The help says run stops cleanly with 0 on Ctrl-C once running, 130 for work cut short; run does so."""
    from vpp_service.cli import EXIT_INTERRUPTED

    text = " ".join(build_parser().format_help().split())
    assert "0 done, also when Ctrl-C or SIGTERM stops run, view or publish once running" in text
    assert f"{EXIT_INTERRUPTED} interrupted before the work was done" in text
    assert "130 interrupted." not in text
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[service]\nout = "{tmp_path / "run"}"\n[zenoh]\nenabled = false\n[source]\ntype = "sim"\n')
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(
        [sys.executable, "-m", "vpp_service", "run", "--config", str(cfg), "--no-summary"],
        cwd=ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stderr is not None
        banner = proc.stderr.readline()  # printed once started
        assert "stop with Ctrl-C" in banner, banner
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 0, err
    assert "vpp-service run: stopped after" in err
