"""deploy/: the pool worker's config, systemd unit and fleet compose file parse with the real CLI and config."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import yaml

from vpp_service.cli import build_parser
from vpp_service.cli.run import overrides_from_args
from vpp_service.service.config import load_config, read_toml, validate_config

DEPLOY = Path(__file__).resolve().parents[1] / "deploy"


def test_pool_example_config_is_a_pool_worker_behind_a_router():
    cfg = load_config(DEPLOY / "pool.example.toml")
    assert cfg.service.pool and cfg.service.pool_deadline_ms > 0
    assert cfg.zenoh.mode == "client" and cfg.zenoh.connect and not cfg.zenoh.listen
    assert cfg.source.name == "zenoh" and [s.name for s in cfg.sinks] == ["zenoh"]


def test_worker_unit_runs_a_pool_worker_with_a_stable_id():
    unit = (DEPLOY / "vpp-worker@.service").read_text()
    (cmd,) = re.findall(r"^ExecStart=(.+)$", unit, re.MULTILINE)
    argv = shlex.split(cmd.replace("%i", "rig0").replace("%H", "host-1"))
    assert argv[0].endswith("vpp-service")
    args = build_parser().parse_args(argv[1:])
    assert args.config == "/etc/vpp-service/pool-rig0.toml"
    data = overrides_from_args(read_toml(DEPLOY / "pool.example.toml"), args)
    cfg = validate_config(data)
    assert cfg.service.pool and cfg.service.worker_id == "host-1-rig0"


def test_fleet_compose_runs_cameras_and_pools_through_the_router():
    fleet = yaml.safe_load((DEPLOY / "fleet.compose.yaml").read_text())
    services = fleet["services"]
    assert "router" in services
    workers = {k: v for k, v in services.items() if k.startswith("worker-")}
    cameras = {k: v for k, v in services.items() if k.startswith("camera-")}
    assert len(workers) >= 2 and len(cameras) == len(workers)
    parser = build_parser()
    for name, svc in workers.items():
        args = parser.parse_args(["run", *svc["command"]])
        assert args.pool and args.zenoh_connect == ["tcp/router:7447"]
        data = overrides_from_args(read_toml(DEPLOY / "pool.example.toml"), args)
        cfg = validate_config(data)
        assert cfg.service.rig == name.removeprefix("worker-") and cfg.service.pool
        assert svc["deploy"]["replicas"] >= 2
    for name, svc in cameras.items():
        args = parser.parse_args([*svc["entrypoint"][1:], *svc["command"]])
        assert args.rig == name.removeprefix("camera-") and args.connect == ["tcp/router:7447"]
