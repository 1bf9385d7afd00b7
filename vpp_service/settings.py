"""Typed, validated settings: build frozen dataclasses from plain mappings.

Every configurable part (VPP, matchers, sources, sinks, the service) describes
its options as a frozen dataclass whose ``__post_init__`` checks value ranges.
:func:`from_mapping` turns a TOML/JSON/CLI mapping into such a dataclass,
rejecting unknown keys and wrong types with an error naming ``section.key``, so
a whole config can be checked before anything starts.
"""

from __future__ import annotations

import dataclasses
import types
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, Literal, TypeVar, Union, get_args, get_origin, get_type_hints

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

T = TypeVar("T", bound="DataclassInstance")


class SettingsError(ValueError):
    """A configuration value is missing, unknown or invalid (names the key)."""


def _as_mapping(value: object, key: str) -> Mapping[str, object]:
    """``value`` if it is a mapping (a TOML table), else a SettingsError naming ``key``."""
    if not isinstance(value, Mapping):
        raise SettingsError(f"{key}: must be a table/mapping, got {type(value).__name__}")
    return value


def _check(value: object, tp: object, key: str) -> object:  # noqa: PLR0911, PLR0912 - one branch per annotation form
    """Validate/coerce ``value`` against annotation ``tp``; return the coerced value."""
    origin = get_origin(tp)
    if tp is Any:
        return value
    if origin is Literal:
        allowed = get_args(tp)
        if value not in allowed:
            raise SettingsError(f"{key}: must be one of {list(allowed)}, got {value!r}")
        return value
    if origin in (Union, types.UnionType):
        args = get_args(tp)
        if value is None and type(None) in args:
            return None
        errors: list[str] = []
        for arg in args:
            if arg is type(None):
                continue
            try:
                return _check(value, arg, key)
            except SettingsError as exc:
                errors.append(str(exc))
        raise SettingsError(errors[0] if len(errors) == 1 else f"{key}: invalid value {value!r}")
    if origin in (tuple, list):
        if not isinstance(value, (list, tuple)):
            raise SettingsError(f"{key}: must be a list, got {type(value).__name__}")
        args = get_args(tp)
        if origin is tuple and args and args[-1] is not Ellipsis:
            if len(value) != len(args):
                raise SettingsError(f"{key}: must have {len(args)} items, got {len(value)}")
            items = [_check(v, a, f"{key}[{i}]") for i, (v, a) in enumerate(zip(value, args, strict=True))]
        else:
            item_tp = args[0] if args else Any
            items = [_check(v, item_tp, f"{key}[{i}]") for i, v in enumerate(value)]
        return tuple(items) if origin is tuple else items
    if origin is dict or tp is dict:
        return dict(_as_mapping(value, key))
    if tp is bool:
        if not isinstance(value, bool):
            raise SettingsError(f"{key}: must be true or false, got {value!r}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise SettingsError(f"{key}: must be an integer, got {value!r}")
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise SettingsError(f"{key}: must be a number, got {value!r}")
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            raise SettingsError(f"{key}: must be a string, got {value!r}")
        return value
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
        A dataclass whose annotations describe the options; its
        ``__post_init__`` may raise ``ValueError`` for out-of-range values.
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
        the message starts with ``section.key``.
    """
    if mapping is None:
        mapping = {}
    if not isinstance(mapping, Mapping):
        raise SettingsError(f"{section or cls.__name__}: must be a table/mapping, got {type(mapping).__name__}")
    prefix = f"{section}." if section else ""
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    unknown = sorted(set(mapping) - set(fields))
    if unknown:
        raise SettingsError(f"{prefix}{unknown[0]}: unknown option; known: {', '.join(sorted(fields))}")
    missing = [
        n
        for n, f in fields.items()
        if n not in mapping and f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
    ]
    if missing:
        raise SettingsError(f"{prefix}{missing[0]}: required option is missing")
    hints = get_type_hints(cls)
    kwargs: dict[str, object] = {}
    for name, value in mapping.items():
        kwargs[name] = _check(value, hints.get(name, Any), prefix + name)
    try:
        return cls(**kwargs)
    except TypeError as exc:  # missing required fields
        raise SettingsError(f"{section or cls.__name__}: {exc}") from None
    except SettingsError:
        raise
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


__all__ = ["SettingsError", "from_mapping", "to_mapping"]
