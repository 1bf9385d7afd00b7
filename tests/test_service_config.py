"""Service config: the example file and the embedded default validate; every error names its key."""

from __future__ import annotations

import argparse
import copy
from pathlib import Path

import pytest

from vpp_service.service.config import DEFAULT_CONFIG, load_config, merge, read_toml, validate_config
from vpp_service.settings import SettingsError

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "deploy" / "config.example.toml"


def test_example_config_validates():
    cfg = load_config(EXAMPLE)
    assert cfg.service.rig == "rig0" and cfg.source.name == "sim" and cfg.matcher.name == "sgbm"
    assert [s.name for s in cfg.sinks] == ["zenoh", "rerun"]
    assert cfg.sinks[1].options.path == "vpp-run/vpp.rrd"  # "{out}" substituted
    assert cfg.zenoh.multicast_scouting is False
    assert cfg.vpp is not None and cfg.vpp.alpha == 0.4


def test_example_documents_every_key():
    """Every option of every section of the default plugins appears in the example file."""
    import dataclasses

    from vpp_service.service.config import QueuesSection, ServiceSection, ZenohSection
    from vpp_service.sources.sim import SimSourceOptions

    text = EXAMPLE.read_text()
    for cls in (ServiceSection, ZenohSection, QueuesSection, SimSourceOptions):
        for f in dataclasses.fields(cls):
            assert f"{f.name} =" in text, f"{cls.__name__}.{f.name} undocumented"


def test_embedded_default_validates():
    cfg = load_config(None)
    assert cfg.source.name == "sim" and cfg.source.options.sensor_options == {"density": 0.05}
    assert cfg.zenoh.listen == ["tcp/127.0.0.1:7447"] and not cfg.zenoh.multicast_scouting
    assert {s.name for s in cfg.sinks} == {"zenoh", "rerun"}
    again = validate_config(cfg.to_dict())
    assert again.to_dict() == cfg.to_dict()


def test_overrides_merge():
    cfg = load_config(None, {"service": {"rig": "front"}, "matcher": {"max_disparity": 64}})
    assert cfg.service.rig == "front" and cfg.matcher.options.max_disparity == 64
    assert merge({"a": {"b": 1, "c": 2}}, {"a": {"b": 3}}) == {"a": {"b": 3, "c": 2}}


def test_max_disparity_auto_is_the_default_and_a_fixed_integer_is_honoured():
    from vpp_service.matchers.disparity_range import AutoRangeOptions

    cfg = load_config(None)
    assert cfg.matcher.raw["max_disparity"] == "auto" and cfg.disparity_range == AutoRangeOptions()
    bare = validate_config({"matcher": {"name": "bm"}})  # no max_disparity key: auto too
    assert bare.disparity_range == AutoRangeOptions()
    tuned = load_config(None, {"matcher": {"auto_range": {"min_depth_m": 0.5, "limit": 192}}})
    assert tuned.disparity_range == AutoRangeOptions(min_depth_m=0.5, limit=192)
    assert validate_config(tuned.to_dict()).disparity_range == tuned.disparity_range
    fixed = load_config(None, {"matcher": {"max_disparity": 96}})
    assert fixed.disparity_range is None and fixed.matcher.options.max_disparity == 96
    assert fixed.to_dict()["matcher"] == {"name": "sgbm", "max_disparity": 96}


def test_reject_log_period_zero_logs_every_reject():
    assert load_config(None, {"service": {"reject_log_period_s": 0.0}}).service.reject_log_period_s == 0.0


def test_vpp_disabled():
    assert load_config(None, {"vpp": {"enabled": False}}).vpp is None


@pytest.mark.parametrize(
    ("change", "key"),
    [
        ({"bogus": {}}, "bogus"),
        ({"service": {"rgi": "x"}}, "service.rgi"),
        ({"service": {"max_frames": "10"}}, "service.max_frames"),
        ({"service": {"max_frames": -1}}, "service.max_frames: got -1; expected >= 0"),
        ({"service": {"rig": "a/b"}}, "service.rig: got 'a/b'; expected 1-64 of"),
        ({"service": {"rig": ".."}}, "service.rig: got '..'"),
        ({"service": {"rig": "-x"}}, "service.rig: got '-x'"),
        ({"service": {"rig": "r" * 300}}, "service.rig: got"),
        ({"service": {"rig": "a b"}}, "service.rig: got 'a b'"),
        ({"service": {"reject_log_period_s": -1.0}}, "service.reject_log_period_s: got -1.0; expected in [0, 3600]"),
        ({"service": {"summary_period_s": 0.0}}, "service.summary_period_s: got 0.0; expected in (0, 3600]"),
        ({"zenoh": {"mode": "mesh"}}, "zenoh.mode"),
        ({"zenoh": {"listen": "tcp/127.0.0.1:1"}}, "zenoh.listen"),
        ({"zenoh": {"listen": ["127.0.0.1"]}}, "zenoh.listen[0]: got '127.0.0.1'; expected an endpoint"),
        ({"zenoh": {"enabled": False}}, "zenoh.enabled"),
        ({"source": {"type": "camera"}}, "source.type"),
        ({"source": {"type": "sim", "rate": 3}}, "source.rate"),
        ({"source": {"type": "sim", "rate_hz": "fast"}}, "source.rate_hz"),
        ({"source": {"type": "sim", "sensor": "radar"}}, "source.sensor: got 'radar'"),
        ({"source": {"type": "sim", "sensor_options": {"densty": 0.1}}}, "source.sensor_options.densty: got"),
        ({"source": {"type": "files"}}, "source.root: got ''; expected a non-empty value"),
        ({"source": {"type": "zenoh", "sync": "fuzzy"}}, "source.sync"),
        ({"source": {"rate_hz": 3}}, "source.type"),
        ({"matcher": {"name": "deep"}}, "matcher.name"),
        ({"matcher": {"name": "sgbm", "max_disp": 3}}, "matcher.max_disp"),
        ({"matcher": {"max_disparity": "wide"}}, "matcher.max_disparity"),
        ({"matcher": {"max_disparity": True}}, "matcher.max_disparity"),
        ({"matcher": {"max_disparity": 0}}, "matcher.max_disparity: got 0; expected in [1, 4096]"),
        ({"matcher": {"max_disparity": 64, "auto_range": {"margin": 8}}}, "matcher.auto_range"),
        ({"matcher": {"auto_range": {"min_depth_m": -1.0}}}, "matcher.auto_range.min_depth_m: got -1.0"),
        ({"matcher": {"auto_range": {"limit": 100}}}, "matcher.auto_range.limit: got 100; expected a multiple of 16"),
        ({"matcher": {"auto_range": {"limit": 0}}}, "matcher.auto_range.limit: got 0; expected in [16, 4096]"),
        ({"matcher": {"auto_range": {"shrink_after": 0}}}, "matcher.auto_range.shrink_after: got 0"),
        ({"matcher": {"auto_range": {"lmit": 64}}}, "matcher.auto_range.lmit"),
        ({"matcher": {"auto_range": 5}}, "matcher.auto_range: got int; expected a table"),
        ({"vpp": {"alpah": 0.3}}, "vpp.alpah: got an unknown option; expected one of"),
        ({"vpp": {"enabled": "yes"}}, "vpp.enabled: got 'yes'; expected true or false"),
        ({"queues": {"input_policy": "newest"}}, "queues.input_policy"),
        ({"queues": {"input_size": 0}}, "queues.input_size: got 0; expected in [1, 10000]"),
        ({"sinks": [{"type": "printer"}]}, "sinks[0].type"),
        ({"sinks": [{"type": "zenoh", "outputs": ["disparity", "normals"]}]}, "sinks[0].outputs[1]: got 'normals'"),
        ({"sinks": [{"outputs": []}]}, "sinks[0].type"),
        ({"sinks": {"type": "zenoh"}}, "sinks: got dict; expected an array of tables"),
        (
            {"sinks": [{"type": "record"}]},
            "sinks[0].dir: got nothing; expected a value",
        ),  # a required option is missing
        ({"sinks": [{"type": "files"}]}, "sinks[0].dir"),
    ],
)
def test_errors_name_the_key(change, key):
    data = copy.deepcopy(DEFAULT_CONFIG)
    for k, v in change.items():
        data[k] = v if k in ("source", "sinks") or not isinstance(v, dict) else merge(data.get(k, {}), v)
    with pytest.raises(SettingsError) as exc:
        validate_config(data)
    assert str(exc.value).startswith(key), str(exc.value)


def test_read_toml_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="config"):
        read_toml(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[service\nrig = 1")
    with pytest.raises(SettingsError, match="invalid TOML"):
        read_toml(bad)


def test_file_config_and_cli_overrides(tmp_path):
    from vpp_service.cli.run import overrides_from_args

    p = tmp_path / "c.toml"
    p.write_text(
        '[service]\nrig = "a"\n[source]\ntype = "sim"\nrate_hz = 0.0\n[matcher]\nname = "bm"\n'
        'max_disparity = 64\n[[sinks]]\ntype = "zenoh"\n'
    )
    args = argparse.Namespace(
        rig="b",
        max_frames=3,
        out=str(tmp_path / "o"),
        no_summary=True,
        source=None,
        matcher="bm",
        zenoh_listen=["tcp/127.0.0.1:1234"],
        zenoh_connect=None,
        sink=["zenoh", "rerun"],
        rerun_save=None,
        input_policy=None,
    )
    cfg = validate_config(overrides_from_args(read_toml(p), args))
    assert (cfg.service.rig, cfg.service.max_frames, cfg.service.summary) == ("b", 3, False)
    assert cfg.matcher.options.max_disparity == 64  # same matcher: options kept
    assert cfg.zenoh.listen == ["tcp/127.0.0.1:1234"]
    assert [s.name for s in cfg.sinks] == ["zenoh", "rerun"]
    assert cfg.sinks[1].options.path == str(tmp_path / "o" / "vpp.rrd")
    args.rerun_save, args.sink = str(tmp_path / "x.rrd"), None
    cfg = validate_config(overrides_from_args(read_toml(p), args))
    assert [s.name for s in cfg.sinks] == ["zenoh", "rerun"] and cfg.sinks[1].options.path.endswith("x.rrd")
    args.rerun_save, args.sink = None, ["files", "record"]  # file sinks get folders under --out
    cfg = validate_config(overrides_from_args(read_toml(p), args))
    assert [s.name for s in cfg.sinks] == ["files", "record"]
    assert [s.options.dir for s in cfg.sinks] == [str(tmp_path / "o" / "frames"), str(tmp_path / "o" / "recording")]
    args.max_disparity = "auto"  # --max-disparity replaces the file's fixed range
    cfg = validate_config(overrides_from_args(read_toml(p), args))
    assert cfg.disparity_range is not None and cfg.matcher.raw["max_disparity"] == "auto"
    args.max_disparity = "48"
    cfg = validate_config(overrides_from_args(read_toml(p), args))
    assert cfg.disparity_range is None and cfg.matcher.options.max_disparity == 48
    args.max_disparity = "lots"
    with pytest.raises(SettingsError, match=r"matcher\.max_disparity"):
        validate_config(overrides_from_args(read_toml(p), args))


def test_cli_check_reports_bad_key(tmp_path, capsys):
    from vpp_service.cli import main

    p = tmp_path / "c.toml"
    p.write_text('[service]\nrigg = "a"\n')
    assert main(["run", "--config", str(p), "--check"]) == 2
    assert "service.rigg" in capsys.readouterr().err
    assert main(["run", "--check", "--max-frames", "2"]) == 0


@pytest.mark.parametrize(
    ("source", "sinks", "where"),
    [
        ({"type": "zenoh"}, [], "source (source 'zenoh')"),
        ({"type": "sim"}, [{"type": "rerun"}, {"type": "zenoh"}], "sinks[1] (sink 'zenoh')"),
    ],
)
def test_zenoh_disabled_names_the_plugin_that_needs_a_session(source, sinks, where):
    data = {"zenoh": {"enabled": False}, "source": source, "sinks": sinks}
    with pytest.raises(SettingsError) as exc:
        validate_config(data)
    assert str(exc.value).startswith(f"zenoh.enabled: {where} needs a zenoh session"), str(exc.value)


def test_zenoh_disabled_is_fine_without_zenoh_plugins(tmp_path):
    cfg = validate_config(
        {
            "zenoh": {"enabled": False},
            "source": {"type": "sim"},
            "sinks": [{"type": "rerun", "path": str(tmp_path / "x.rrd")}],
        }
    )
    assert not cfg.zenoh.enabled and [s.name for s in cfg.sinks] == ["rerun"]


@pytest.mark.parametrize(
    ("sensor", "options", "message"),
    [
        ("radar", {}, "source.sensor: got 'radar'; expected one of 'lidar', 'tof', 'uniform', 'none'"),
        ("uniform", {"densty": 0.1}, "source.sensor_options.densty: got an unknown option; expected one of density, "),
        ("uniform", {"density": 2.0}, "source.sensor_options.density: got 2.0; expected in (0, 1]"),
    ],
)
def test_sim_source_checks_its_own_sensor(sensor, options, message):
    """The sim source's check_options builds the sensor: the error names the config key."""
    from vpp_service.sources import parse_source_options

    with pytest.raises(SettingsError) as exc:
        parse_source_options("sim", {"sensor": sensor, "sensor_options": options}, "source")
    assert str(exc.value).startswith(message), str(exc.value)
    opts = parse_source_options("sim", {"sensor": "none", "sensor_options": options}, "source")
    assert opts.sensor == "none"  # no sensor: its options are not checked


def test_depth_filter_section():
    cfg = load_config(EXAMPLE)
    assert cfg.depth_filter is not None and cfg.depth_filter.mode == "auto"
    tuned = load_config(None, {"depth_filter": {"mode": "see-through", "window_w": 9, "margin": 0.2}})
    assert tuned.depth_filter is not None
    assert (tuned.depth_filter.mode, tuned.depth_filter.window_w, tuned.depth_filter.margin) == ("see-through", 9, 0.2)
    assert validate_config(tuned.to_dict()).depth_filter == tuned.depth_filter
    data = copy.deepcopy(DEFAULT_CONFIG)
    data["source"] |= {"sensor": "lidar", "sensor_options": {"pose": "kitti"}}
    assert validate_config(data).source.options.sensor_options == {"pose": "kitti"}


@pytest.mark.parametrize(
    ("section", "match"),
    [
        ({"mode": "always"}, r"depth_filter\.mode"),
        ({"window_w": 4}, "window_w"),
        ({"window_h": "15"}, r"depth_filter\.window_h"),
        ({"margin": -0.5}, "margin"),
        ({"radius": 3}, r"depth_filter\.radius"),
    ],
)
def test_depth_filter_errors_name_the_key(section, match):
    with pytest.raises(SettingsError, match=match):
        load_config(None, {"depth_filter": section})


def test_lidar_pose_is_validated_with_the_config():
    data = copy.deepcopy(DEFAULT_CONFIG)
    data["source"] |= {"sensor": "lidar", "sensor_options": {"pose": "nowhere"}}
    with pytest.raises(SettingsError, match="pose"):
        validate_config(data)
