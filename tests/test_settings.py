"""Tests of vpp_service.settings: declared option constraints and their one message format."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated, Literal

import pytest

from vpp_service.settings import (
    Each,
    IsFile,
    Matches,
    MultipleOf,
    NonEmpty,
    Odd,
    OneOf,
    OptionError,
    Options,
    Range,
    Satisfies,
    SettingsError,
    Unique,
    constraints,
    from_mapping,
    reject,
)


@dataclass(frozen=True)
class Inner(Options):
    size: Annotated[int, Range(1, 64)] = 8


@dataclass(frozen=True)
class Demo(Options):
    patch: Annotated[int, Range(1), Odd()] = 3
    alpha: Annotated[float, Range(0.0, 1.0, lo_open=True)] = 0.5
    mode: Annotated[str, OneOf("fast", "exact")] = "fast"
    kind: Literal["a", "b"] = "a"
    step: Annotated[int, MultipleOf(16)] = 16
    name: Annotated[str, NonEmpty()] = "x"
    tags: Annotated[list[str], Unique(), Each(OneOf("l", "r"))] = field(default_factory=list)
    word: Annotated[str, Matches(r"[a-z]+", "lower-case letters")] = "abc"
    even: Annotated[int, Satisfies(lambda v: v % 2 == 0, "an even integer")] = 2
    file: Annotated[str, IsFile()] = ""
    limit: Annotated[float | None, Range(0.0)] = None
    lo: float = 0.0
    hi: float = 1.0
    flag: bool = False
    inner: Inner = field(default_factory=Inner)

    def cross_check(self) -> None:
        if self.hi <= self.lo:
            raise reject("hi", self.hi, f"> lo ({self.lo})")


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"patch": 4}, "patch: got 4; expected an odd integer"),
        ({"patch": 0}, "patch: got 0; expected >= 1"),
        ({"alpha": 0.0}, r"alpha: got 0.0; expected in \(0, 1\]"),
        ({"alpha": float("nan")}, r"alpha: got nan; expected in \(0, 1\]"),
        ({"mode": "slow"}, "mode: got 'slow'; expected one of 'fast', 'exact'"),
        ({"kind": "c"}, "kind: got 'c'; expected one of 'a', 'b'"),
        ({"step": 24}, "step: got 24; expected a multiple of 16"),
        ({"name": "  "}, "name: got '  '; expected a non-empty value"),
        ({"tags": ["l", "l"]}, r"tags: got \['l', 'l'\]; expected no duplicate items"),
        ({"tags": ["l", "x"]}, r"tags\[1\]: got 'x'; expected one of 'l', 'r'"),
        ({"word": "ABC"}, "word: got 'ABC'; expected lower-case letters"),
        ({"even": 3}, "even: got 3; expected an even integer"),
        ({"file": "/no/such/file"}, "file: got '/no/such/file'; expected an existing file"),
        ({"limit": -1.0}, "limit: got -1.0; expected >= 0"),
        ({"hi": 0.0}, r"hi: got 0.0; expected > lo \(0.0\)"),
    ],
)
def test_direct_build_names_the_field(kwargs, message):
    with pytest.raises(OptionError, match=f"^{message}$"):
        Demo(**kwargs)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"patch": 3.0}, "patch: got 3.0; expected an integer"),
        ({"flag": 1}, "flag: got 1; expected true or false"),
        ({"alpha": "0.5"}, "alpha: got '0.5'; expected a number"),
        ({"limit": "x"}, "limit: got 'x'; expected a number or none"),
    ],
)
def test_wrong_type_is_a_type_error_too(kwargs, message):
    with pytest.raises(TypeError, match=f"^{message}$"):
        Demo(**kwargs)


def test_none_skips_markers_and_ints_pass_for_floats():
    d = Demo(limit=None, alpha=1, lo=-1)
    assert (d.limit, d.alpha) == (None, 1)


@pytest.mark.parametrize(
    ("mapping", "message"),
    [
        ({"patch": 2}, r"sec\.patch: got 2; expected an odd integer"),
        ({"patch": "3"}, r"sec\.patch: got '3'; expected an integer"),
        ({"tags": ["r", "q"]}, r"sec\.tags\[1\]: got 'q'; expected one of 'l', 'r'"),
        ({"hi": -1}, r"sec\.hi: got -1.0; expected > lo \(0.0\)"),
        ({"inner": {"size": 65}}, r"sec\.inner\.size: got 65; expected in \[1, 64\]"),
        ({"bogus": 1}, r"sec\.bogus: got an unknown option; expected one of alpha, even, "),
        ({"inner": 3}, r"sec\.inner: got int; expected a table/mapping"),
    ],
)
def test_from_mapping_puts_the_section_first(mapping, message):
    with pytest.raises(SettingsError, match=f"^{message}"):
        from_mapping(Demo, mapping, section="sec")


def test_from_mapping_missing_required_option():
    @dataclass(frozen=True)
    class Needs(Options):
        dir: Annotated[str, NonEmpty()]

    with pytest.raises(SettingsError, match=r"^s\.dir: got nothing; expected a value \(a required option\)$"):
        from_mapping(Needs, {}, section="s")
    assert from_mapping(Needs, {"dir": "out"}).dir == "out"


def test_constraints_describe_each_field():
    c = constraints(Demo)
    assert c["patch"] == "an integer; >= 1; an odd integer"
    assert c["alpha"] == "a number; in (0, 1]"
    assert c["tags"] == "no duplicate items; items one of 'l', 'r'"
    assert "lo" in c and "inner" not in c
