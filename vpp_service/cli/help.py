"""Help text of the ``vpp-service`` commands: plain text from docstrings, defaults shown."""

from __future__ import annotations

import argparse
import re

_ROLE = re.compile(r":[a-z]+:`~?(?:[\w.]+\.)?([^`]+)`")  # :data:`a.b.NAME` -> NAME
_LITERAL = re.compile(r"``([^`]+)``")  # ``text`` -> text


class HelpFormatter(argparse.RawDescriptionHelpFormatter, argparse.ArgumentDefaultsHelpFormatter):
    """Keeps the description's line breaks and appends ``(default: ...)`` to every flag with a default."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        help_text = action.help or ""
        if action.default in (None, False, [], argparse.SUPPRESS) or "default" in help_text:
            return help_text
        return super()._get_help_string(action)


def plain(doc: str | None) -> str:
    """``doc`` without reStructuredText markup (roles, double back-quotes, ``::``), for ``--help``."""
    text = _LITERAL.sub(r"\1", _ROLE.sub(r"\1", doc or ""))
    return re.sub(r"::$", ":", text, flags=re.MULTILINE).strip()


__all__ = ["HelpFormatter", "plain"]
