"""The ``run`` sub-command's Rerun flags, parsed by the real parser and validated as a config."""

from __future__ import annotations

import pytest

from vpp_service.cli import build_parser
from vpp_service.cli.run import overrides_from_args
from vpp_service.service.config import DEFAULT_CONFIG, validate_config

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
