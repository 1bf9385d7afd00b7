"""Plugin option hooks: parse_options runs the dataclass checks, then the plugin's own check_options."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import pytest

from vpp_service.plugin import Plugin, PluginContext, parse_plugin_options
from vpp_service.registry import Registry
from vpp_service.settings import SettingsError


@dataclass(frozen=True)
class RangeOptions:
    lo: int = 0
    hi: int = 10

    def __post_init__(self) -> None:
        if self.lo < 0:
            raise ValueError(f"lo must be >= 0, got {self.lo}")


class RangePlugin(Plugin):
    """A plugin whose options need a cross-field check the dataclass does not make."""

    Options = RangeOptions
    checked: ClassVar[list[str]] = []

    @classmethod
    def check_options(cls, options: RangeOptions, section: str) -> None:
        cls.checked.append(section)
        if options.hi <= options.lo:
            raise SettingsError(f"{section}.hi: must be > lo ({options.lo}), got {options.hi}")


def registry() -> Registry[Plugin]:
    reg: Registry[Plugin] = Registry("thing")
    reg.register("range")(RangePlugin)
    return reg


def test_parse_options_runs_the_plugin_check_after_the_dataclass():
    RangePlugin.checked.clear()
    opts = parse_plugin_options(registry(), "range", {"lo": 2, "hi": 5}, "things[0]")
    assert opts == RangeOptions(2, 5) and RangePlugin.checked == ["things[0]"]
    with pytest.raises(SettingsError) as exc:
        parse_plugin_options(registry(), "range", {"lo": 5, "hi": 5}, "things[1]")
    assert str(exc.value).startswith("things[1].hi: must be > lo")


def test_dataclass_errors_come_first_and_name_the_section():
    RangePlugin.checked.clear()
    with pytest.raises(SettingsError, match=r"^things\[0\]: lo must be >= 0"):
        RangePlugin.parse_options({"lo": -1}, "things[0]")
    with pytest.raises(SettingsError, match=r"^things\[0\]\.size: got an unknown option; expected one of hi, lo$"):
        RangePlugin.parse_options({"size": 1}, "things[0]")
    assert RangePlugin.checked == []  # the hook sees only well-formed options


def test_defaults_when_no_options():
    assert RangePlugin.parse_options(None, "t") == RangeOptions()


def test_plugin_defaults_need_no_session_and_check_nothing():
    assert Plugin.needs_session is False
    assert Plugin.check_options(object(), "x") is None
    p = RangePlugin(RangeOptions(), PluginContext())
    assert p.stats() == {} and p.context.rig == "rig0"


def test_a_registered_non_plugin_cannot_parse_options():
    reg: Registry = Registry("thing")
    reg.register("func")(lambda options, context: None)
    with pytest.raises(TypeError, match="not as a Plugin class"):
        parse_plugin_options(reg, "func", {}, "things[0]")
