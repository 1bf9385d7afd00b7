"""Typed, validated settings: build frozen dataclasses from plain mappings.

Every configurable part (VPP, matchers, sources, sinks, the service) describes
its options as a frozen dataclass deriving from :class:`Options`.  Each field
declares its constraints beside its type with :data:`typing.Annotated` markers
(:class:`Range`, :class:`OneOf`, :class:`Odd`, :class:`NonEmpty`, ...), and one
validator, :func:`validate`, reads them when the dataclass is built -- from a
config file through :func:`from_mapping` or directly in Python::

    @dataclass(frozen=True)
    class Options(settings.Options):
        patch: Annotated[int, Range(1), Odd()] = 3
        mode: Annotated[str, OneOf("fast", "exact")] = "fast"

Rules that tie two fields together cannot be declared; an options class states
them in a short :meth:`Options.cross_check` method that the validator calls
after the per-field checks (a subclass calls ``super().cross_check()`` first).

Every rejected value gives one message format, ``section.key: got X; expected Y``
(an :class:`OptionError`).  ``section`` is the dotted config path given to
:func:`from_mapping` (e.g. ``sinks[0]``); a dataclass built directly in Python
has no section, and the message starts with the field name alone.
:func:`constraints` gives each field's ``expected`` text, for help and docs.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import numbers
import re
import types
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import (
    TYPE_CHECKING,
    Any,
    Literal,
    TypeVar,
    Union,
    get_args,
    get_origin,
    get_type_hints,
)

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

T = TypeVar("T", bound="DataclassInstance")


class SettingsError(ValueError):
    """A configuration value is missing, unknown or invalid (names the key)."""


class OptionError(SettingsError):
    """One option's value is rejected: ``key: got X; expected Y``.

    Parameters
    ----------
    key : str
        The option's name (``section.key`` once :func:`from_mapping` adds the section).
    got : str
        What was given, as the message shows it (usually ``repr(value)``).
    expected : str
        What is accepted, e.g. ``"in [1, 64]"`` or ``"one of 'fgd', 'no'"``.
    """

    def __init__(self, key: str, got: str, expected: str) -> None:
        self.key, self.got, self.expected = key, got, expected
        super().__init__(f"{key}: got {got}; expected {expected}")

    def within(self, section: str) -> OptionError:
        """The same error with ``section.`` put before the key (no-op for an empty section)."""
        if not section:
            return self
        key = self.key if self.key.startswith("[") else f".{self.key}"
        return type(self)(f"{section}{key}", self.got, self.expected)


class OptionTypeError(OptionError, TypeError):
    """An option's value has the wrong type (also a :class:`TypeError`)."""


def reject(key: str, value: object, expected: str) -> OptionError:
    """The :class:`OptionError` for ``value`` of option ``key`` (to ``raise`` from a cross-field check)."""
    return OptionError(key, repr(value), expected)


# --------------------------------------------------------------------------- markers


class Constraint:
    """Base of the markers put in ``Annotated[...]`` beside a field's type.

    A marker says what it accepts (:attr:`expected`) and tests one value
    (:meth:`accepts`); ``None`` (an unset optional field) is never tested.
    """

    #: Human-readable description of the accepted values (the ``expected Y`` of the message).
    expected: str = ""

    def accepts(self, value: Any) -> bool:  # pragma: no cover - overridden
        """Whether ``value`` satisfies the constraint."""
        raise NotImplementedError


def _fmt(v: float) -> str:
    """``4096`` for 4096.0, ``0.5`` for 0.5."""
    return str(int(v)) if isinstance(v, float) and v.is_integer() else str(v)


@dataclasses.dataclass(frozen=True)
class Range(Constraint):
    """A finite number ``lo <= v <= hi`` (either bound may be None; ``*_open`` makes it strict)."""

    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False

    @property
    def expected(self) -> str:  # type: ignore[override]
        """``in [lo, hi]`` / ``in (lo, hi]`` / ``>= lo`` / ``> lo`` / ``<= hi``."""
        if self.lo is not None and self.hi is not None:
            lb, rb = "(" if self.lo_open else "[", ")" if self.hi_open else "]"
            return f"in {lb}{_fmt(self.lo)}, {_fmt(self.hi)}{rb}"
        if self.lo is not None:
            return f"{'>' if self.lo_open else '>='} {_fmt(self.lo)}"
        if self.hi is not None:
            return f"{'<' if self.hi_open else '<='} {_fmt(self.hi)}"
        return "a finite number"

    def accepts(self, value: Any) -> bool:
        """Whether ``value`` is a finite number inside the range."""
        if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
            return False
        value = float(value)
        if self.lo is not None and (value < self.lo or (self.lo_open and value == self.lo)):
            return False
        return self.hi is None or not (value > self.hi or (self.hi_open and value == self.hi))


class OneOf(Constraint):
    """One of the given values."""

    def __init__(self, *values: object) -> None:
        self.values = values
        self.expected = "one of " + ", ".join(repr(v) for v in values)

    def accepts(self, value: Any) -> bool:
        """Whether ``value`` is one of the values (not ``True`` for ``1``)."""
        return any(value == v and isinstance(value, bool) == isinstance(v, bool) for v in self.values)


class Odd(Constraint):
    """An odd integer."""

    expected = "an odd integer"

    def accepts(self, value: Any) -> bool:
        """Whether ``value`` is odd."""
        return int(value) % 2 == 1


class MultipleOf(Constraint):
    """An integer multiple of ``n``."""

    def __init__(self, n: int) -> None:
        self.n = n
        self.expected = f"a multiple of {n}"

    def accepts(self, value: Any) -> bool:
        """Whether ``n`` divides ``value``."""
        return int(value) % self.n == 0


class NonEmpty(Constraint):
    """A string with a non-blank character, or a list with at least one item."""

    expected = "a non-empty value"

    def accepts(self, value: Any) -> bool:
        """Whether ``value`` is not empty (nor blank)."""
        return bool(value.strip()) if isinstance(value, str) else len(value) > 0


class Unique(Constraint):
    """A list without duplicates."""

    expected = "no duplicate items"

    def accepts(self, value: Any) -> bool:
        """Whether the items of ``value`` are distinct."""
        return len(set(value)) == len(value)


class Matches(Constraint):
    """A string the regular expression ``pattern`` matches whole; ``expected`` describes it."""

    def __init__(self, pattern: str, expected: str) -> None:
        self.pattern = re.compile(pattern)
        self.expected = expected

    def accepts(self, value: Any) -> bool:
        """Whether ``pattern`` matches all of ``value``."""
        return isinstance(value, str) and self.pattern.fullmatch(value) is not None


class IsFile(Constraint):
    """The path of an existing file (an empty string means "none" and passes)."""

    expected = "an existing file"

    def accepts(self, value: Any) -> bool:
        """Whether ``value`` is empty or names an existing file."""
        return not value or Path(value).is_file()


class Each(Constraint):
    """Every item of a list satisfies ``markers`` (the message names the item, ``key[i]``)."""

    def __init__(self, *markers: Constraint) -> None:
        self.markers = markers
        self.expected = "items " + ", ".join(m.expected for m in markers)

    def accepts(self, value: Any) -> bool:  # checked item by item in _check_markers
        """Whether every item satisfies every marker."""
        return all(m.accepts(v) for v in value for m in self.markers)


class Satisfies(Constraint):
    """A value ``check`` accepts: ``check(value)`` returns False or raises ValueError/TypeError to refuse it.

    For rules kept in one function because other code uses them too (a topic
    name, a file-name pattern) or too small for a marker of their own;
    ``expected`` says what they accept.
    """

    def __init__(self, check: Callable[[Any], object], expected: str) -> None:
        self.check = check
        self.expected = expected

    def accepts(self, value: Any) -> bool:
        """Whether ``check(value)`` returns without raising."""
        try:
            return self.check(value) is not False
        except (ValueError, TypeError):
            return False


# --------------------------------------------------------------------------- the validator


@dataclasses.dataclass(frozen=True)
class _Field:
    name: str
    tp: object  # the type without Annotated
    markers: tuple[Constraint, ...]


@functools.cache
def _fields(cls: type) -> tuple[_Field, ...]:
    hints = get_type_hints(cls, include_extras=True)
    out = []
    for f in dataclasses.fields(cls):
        tp = hints.get(f.name, Any)
        markers: tuple[Constraint, ...] = ()
        if hasattr(tp, "__metadata__"):
            markers = tuple(m for m in tp.__metadata__ if isinstance(m, Constraint))
            tp = get_args(tp)[0]
        out.append(_Field(f.name, tp, markers))
    return tuple(out)


def _scalar_expected(tp: object) -> str | None:  # noqa: PLR0911 - one branch per annotation form
    """The type word of a scalar annotation (bool, int, float, str, Literal, optional), else None."""
    if tp is bool:
        return "true or false"
    if tp is int:
        return "an integer"
    if tp is float:
        return "a number"
    if tp is str:
        return "a string"
    if get_origin(tp) is Literal:
        return "one of " + ", ".join(repr(a) for a in get_args(tp))
    if tp is dict or get_origin(tp) is dict:
        return "a table"
    if get_origin(tp) in (Union, types.UnionType):
        words = [_scalar_expected(a) for a in get_args(tp) if a is not type(None)]
        if all(words) and len(words) == 1:
            return f"{words[0]} or none"
    return None


def _type_ok(value: object, tp: object) -> bool:  # noqa: PLR0911 - one branch per annotation form
    """Whether ``value`` fits the scalar annotation ``tp`` (ints pass for floats)."""
    if tp is bool:
        return isinstance(value, bool)
    if tp is int:
        return isinstance(value, numbers.Integral) and not isinstance(value, bool)
    if tp is float:
        return isinstance(value, numbers.Real) and not isinstance(value, bool)
    if tp is str:
        return isinstance(value, str)
    if get_origin(tp) is Literal:
        return OneOf(*get_args(tp)).accepts(value)
    if tp is dict or get_origin(tp) is dict:
        return isinstance(value, dict)
    if get_origin(tp) in (Union, types.UnionType):
        return any(value is None if a is type(None) else _type_ok(value, a) for a in get_args(tp))
    return True


def _check_markers(key: str, value: Any, markers: tuple[Constraint, ...]) -> None:
    for m in markers:
        if isinstance(m, Each):
            for i, item in enumerate(value):
                _check_markers(f"{key}[{i}]", item, m.markers)
        elif not m.accepts(value):
            raise OptionError(key, repr(value), m.expected)


def validate(obj: DataclassInstance) -> None:
    """Check every field of ``obj`` against its type and markers, then its cross-field rules.

    Raises
    ------
    OptionTypeError
        A scalar field (bool, int, float, str, a Literal, or one of them or None)
        holds a value of another type.
    OptionError
        A value a marker or :meth:`Options.cross_check` refuses.
    """
    for f in _fields(type(obj)):
        value = getattr(obj, f.name)
        expected = _scalar_expected(f.tp)
        if expected is not None and not _type_ok(value, f.tp):
            kind = OptionError if get_origin(f.tp) is Literal else OptionTypeError
            raise kind(f.name, repr(value), expected)
        if value is not None:
            _check_markers(f.name, value, f.markers)
    cross = getattr(obj, "cross_check", None)
    if cross is not None:
        cross()


def constraints(cls: type) -> dict[str, str]:
    """Each field's accepted values in words (``{"patch": "an integer; >= 1; an odd integer"}``), for help/docs."""
    out = {}
    for f in _fields(cls):
        words = [w for w in (_scalar_expected(f.tp), *(m.expected for m in f.markers)) if w]
        if words:
            out[f.name] = "; ".join(words)
    return out


class Options:
    """Base of the options dataclasses: validates the declared constraints when built.

    A subclass is a frozen dataclass whose fields carry ``Annotated`` markers;
    building it runs :func:`validate`.  Override :meth:`cross_check` for the
    rules that tie fields together.
    """

    def __post_init__(self) -> None:
        validate(self)  # type: ignore[arg-type]

    def cross_check(self) -> None:
        """Rules between fields, run after the per-field checks; raise :func:`reject` errors."""


# --------------------------------------------------------------------------- mappings


def _as_mapping(value: object, key: str) -> Mapping[str, object]:
    """``value`` if it is a mapping (a TOML table), else an OptionError naming ``key``."""
    if not isinstance(value, Mapping):
        raise OptionError(key, type(value).__name__, "a table/mapping")
    return value


def _check(value: object, tp: object, key: str) -> object:  # noqa: PLR0911, PLR0912 - one branch per annotation form
    """Validate/coerce ``value`` against annotation ``tp``; return the coerced value."""
    if hasattr(tp, "__metadata__"):  # Annotated: the markers are checked when the dataclass is built
        tp = get_args(tp)[0]
    origin = get_origin(tp)
    if tp is Any:
        return value
    if origin is Literal:
        allowed = get_args(tp)
        if value not in allowed:
            raise OptionError(key, repr(value), "one of " + ", ".join(repr(a) for a in allowed))
        return value
    if origin in (Union, types.UnionType):
        args = get_args(tp)
        if value is None and type(None) in args:
            return None
        errors: list[OptionError] = []
        for arg in args:
            if arg is type(None):
                continue
            try:
                return _check(value, arg, key)
            except OptionError as exc:
                errors.append(exc)
        if len(errors) == 1:
            raise errors[0]
        raise OptionError(key, repr(value), " or ".join(e.expected for e in errors))
    if origin in (tuple, list):
        if not isinstance(value, (list, tuple)):
            raise OptionError(key, type(value).__name__, "a list")
        args = get_args(tp)
        if origin is tuple and args and args[-1] is not Ellipsis:
            if len(value) != len(args):
                raise OptionError(key, f"{len(value)} items", f"{len(args)} items")
            items = [_check(v, a, f"{key}[{i}]") for i, (v, a) in enumerate(zip(value, args, strict=True))]
        else:
            item_tp = args[0] if args else Any
            items = [_check(v, item_tp, f"{key}[{i}]") for i, v in enumerate(value)]
        return tuple(items) if origin is tuple else items
    if origin is dict or tp is dict:
        return dict(_as_mapping(value, key))
    if tp in (bool, int, float, str):
        if not _type_ok(value, tp):
            raise OptionError(key, repr(value), str(_scalar_expected(tp)))
        return float(value) if tp is float else value  # type: ignore[arg-type]
    if isinstance(tp, type) and dataclasses.is_dataclass(tp):
        if isinstance(value, tp):
            return value
        return from_mapping(tp, _as_mapping(value, key), section=key)
    return value


def from_mapping(cls: type[T], mapping: Mapping[str, object] | None, section: str = "") -> T:
    """Build the frozen dataclass ``cls`` from ``mapping``.

    Parameters
    ----------
    cls : type
        A dataclass whose annotations describe the options (an :class:`Options`
        subclass validates its declared constraints when built).
    mapping : Mapping or None
        Option values; missing keys take the dataclass defaults.
    section : str
        Dotted prefix used in error messages (e.g. ``"sinks.rerun"``).

    Returns
    -------
    An instance of ``cls``.

    Raises
    ------
    SettingsError
        Unknown key, wrong type, missing required key or out-of-range value;
        the message starts with ``section.key`` (an :class:`OptionError`).
    """
    if mapping is None:
        mapping = {}
    if not isinstance(mapping, Mapping):
        raise OptionError(section or cls.__name__, type(mapping).__name__, "a table/mapping")
    prefix = f"{section}." if section else ""
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    unknown = sorted(set(mapping) - set(fields))
    if unknown:
        raise OptionError(prefix + unknown[0], "an unknown option", "one of " + ", ".join(sorted(fields)))
    missing = [
        n
        for n, f in fields.items()
        if n not in mapping and f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
    ]
    if missing:
        raise OptionError(prefix + missing[0], "nothing", "a value (a required option)")
    hints = get_type_hints(cls)
    kwargs: dict[str, object] = {}
    for name, value in mapping.items():
        kwargs[name] = _check(value, hints.get(name, Any), prefix + name)
    try:
        return cls(**kwargs)
    except OptionError as exc:
        raise exc.within(section) from None
    except SettingsError:
        raise
    except TypeError as exc:  # missing required fields
        raise SettingsError(f"{section or cls.__name__}: {exc}") from None
    except ValueError as exc:
        raise SettingsError(f"{section + ': ' if section else ''}{exc}") from None


def to_mapping(obj: DataclassInstance) -> dict[str, object]:
    """Plain-dict form of a settings dataclass (nested dataclasses become dicts, tuples become lists)."""

    def conv(v: object) -> object:
        if dataclasses.is_dataclass(v) and not isinstance(v, type):
            return to_mapping(v)
        if isinstance(v, (tuple, list)):
            return [conv(x) for x in v]
        return v

    return {f.name: conv(getattr(obj, f.name)) for f in dataclasses.fields(obj)}


__all__ = [
    "Constraint",
    "Each",
    "IsFile",
    "Matches",
    "MultipleOf",
    "NonEmpty",
    "Odd",
    "OneOf",
    "OptionError",
    "OptionTypeError",
    "Options",
    "Range",
    "Satisfies",
    "SettingsError",
    "Unique",
    "constraints",
    "from_mapping",
    "reject",
    "to_mapping",
    "validate",
]
