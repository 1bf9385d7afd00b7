"""``KEY=VALUE`` flag values (``--matcher-opt``, ``--sensor-opt``, ``--dataset-opt``) shared by the commands."""

from __future__ import annotations

import argparse
import json


def key_value(text: str) -> tuple[str, object]:
    """Parse ``KEY=VALUE``; VALUE is read as JSON when it is JSON (``16``, ``true``, ``[1, 2]``), else kept as text.

    Raises
    ------
    argparse.ArgumentTypeError
        No ``=`` in ``text``.
    """
    if "=" not in text:
        raise argparse.ArgumentTypeError(f"expected KEY=VALUE, got {text!r}")
    key, _, value = text.partition("=")
    try:
        parsed = json.loads(value)
    except json.JSONDecodeError:
        parsed = value
    return key.strip(), parsed


__all__ = ["key_value"]
