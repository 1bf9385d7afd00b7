"""``vpp-service run``: --check checks paths, --source zenoh is lossless, start-up and closing lines."""

from __future__ import annotations

import json

import pytest

from vpp_service.cli import EXIT_STARTUP, build_parser, main
from vpp_service.cli.run import closing_line, overrides_from_args, startup_line
from vpp_service.service.config import DEFAULT_CONFIG, validate_config


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
