"""Write the small config mappings the tests build as TOML (no TOML writer is a dependency)."""

from __future__ import annotations

import json
from collections.abc import Mapping


def _value(v: object) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float, str)):
        return json.dumps(v)
    if isinstance(v, Mapping):
        return "{" + ", ".join(f"{k} = {_value(x)}" for k, x in v.items()) + "}"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    raise TypeError(f"no TOML form for {type(v).__name__}")


def toml_dumps(data: Mapping[str, object]) -> str:
    """``data`` as TOML: top-level non-table keys first (inline values), then one ``[table]`` per mapping."""
    lines = [f"{k} = {_value(v)}" for k, v in data.items() if not isinstance(v, Mapping)]
    for k, v in data.items():
        if isinstance(v, Mapping):
            lines.append(f"[{k}]")
            lines.extend(f"{kk} = {_value(vv)}" for kk, vv in v.items())
    return "\n".join(lines) + "\n"
