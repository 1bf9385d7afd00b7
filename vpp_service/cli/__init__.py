"""The ``vpp-service`` command.

Each sub-command lives in its own module of this package and exposes
``add_parser(subparsers)`` (which sets ``func`` on its parser); this module only
dispatches. :func:`main` first sets the OpenMP wait policy
(:func:`vpp_service.threads.configure_openmp`): it must run before any kernel
module is imported, so neither this module nor the sub-command modules import
kernels at module level.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys

from vpp_service.threads import configure_openmp

#: Sub-command modules, in the order ``--help`` lists them.
COMMANDS = ("run", "publish", "status", "view", "eval", "demo")


def build_parser() -> argparse.ArgumentParser:
    """The top-level argument parser with every available sub-command."""
    parser = argparse.ArgumentParser(
        prog="vpp-service",
        description="Virtual Pattern Projection: stereo + sparse depth fusion service.",
    )
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log output (-vv for debug)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        try:
            module = importlib.import_module(f"{__name__}.{name}")
        except ModuleNotFoundError as exc:  # a sub-command not built into this install
            if exc.name != f"{__name__}.{name}":
                raise
            continue
        module.add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``vpp-service`` console script."""
    configure_openmp()  # before libgomp loads, i.e. before any sub-command imports a kernel
    parser = build_parser()
    args = parser.parse_args(argv)
    level = logging.WARNING - 10 * min(args.verbose, 2)
    logging.basicConfig(level=level, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        return 130
    except (ValueError, FileNotFoundError) as exc:
        print(f"vpp-service {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
