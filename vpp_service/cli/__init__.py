"""The ``vpp-service`` command.

Each sub-command lives in its own module of this package and exposes
``add_parser(subparsers)`` (which sets ``func`` on its parser); this module only
dispatches and maps failures to exit statuses (:data:`EXIT_STARTUP`, :data:`EXIT_FAILURE`).
:func:`main` first sets the OpenMP wait policy
(:func:`vpp_service.threads.configure_openmp`): it must run before any kernel
module is imported, so neither this module nor the sub-command modules import
kernels at module level.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
from typing import Any

from vpp_service import __version__
from vpp_service.cli.help import HelpFormatter, plain
from vpp_service.errors import StartupError
from vpp_service.threads import configure_openmp

#: Sub-command modules, in the order ``--help`` lists them.
COMMANDS = ("run", "publish", "status", "view", "eval", "demo", "models")

#: Exit status of a configuration or start-up error (bad flag, bad config key, missing path, Zenoh cannot open).
EXIT_STARTUP = 2
#: Exit status of a failure after start-up (nobody replied or subscribed, an unexpected error while running).
EXIT_FAILURE = 1
#: Exit status of a command interrupted (Ctrl-C) before its work was done: during start-up, ``publish``'s
#: wait for a subscriber, ``eval`` and ``demo``. ``run``, ``view`` and ``publish`` once running stop cleanly: 0.
EXIT_INTERRUPTED = 130

EPILOG = f"""exit status: 0 done, also when Ctrl-C or SIGTERM stops run, view or publish once running (a clean stop);
{EXIT_STARTUP} configuration or start-up error (a message on stderr);
{EXIT_FAILURE} failure while running (e.g. the source died, no service answered, no subscriber);
{EXIT_INTERRUPTED} interrupted before the work was done: Ctrl-C during start-up, during publish's wait for a
subscriber, or during eval (the scenes that finished are written, marked partial) or demo.
Every command meets the others on tcp/127.0.0.1:7447 unless told otherwise ($VPP_SERVICE_ENDPOINT)."""


class _SubParsers(argparse._SubParsersAction):  # type: ignore[type-arg]
    """Adds ``-v/--verbose`` to every sub-command (so it works after it too); plain help with defaults."""

    def add_parser(self, name: str, **kwargs: Any) -> argparse.ArgumentParser:
        kwargs["description"] = plain(kwargs.get("description"))  # docstrings -> plain text, defaults shown
        kwargs["formatter_class"] = HelpFormatter
        parser = super().add_parser(name, **kwargs)
        parser.add_argument(
            "-v", "--verbose", action="count", default=argparse.SUPPRESS, help="more log output (-vv for debug)"
        )
        return parser


def build_parser() -> argparse.ArgumentParser:
    """The top-level argument parser with every available sub-command."""
    parser = argparse.ArgumentParser(
        prog="vpp-service",
        description="Virtual Pattern Projection: stereo + sparse depth fusion service.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log output (-vv for debug)")
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    parser.register("action", "parsers", _SubParsers)
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
        return EXIT_STARTUP
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED
    except (ValueError, OSError, StartupError) as exc:  # config, paths, endpoints: before anything ran
        print(f"vpp-service {args.command}: error: {_message(exc)}", file=sys.stderr)
        return EXIT_STARTUP
    except Exception as exc:
        logging.getLogger(__name__).debug("traceback", exc_info=True)
        print(f"vpp-service {args.command}: failed: {type(exc).__name__}: {_message(exc)}", file=sys.stderr)
        return EXIT_FAILURE


def _message(exc: BaseException) -> str:
    """``exc``'s whole message, every line (its type when it has none): a list after "looked for:" stays."""
    text = str(exc).strip()
    return text or type(exc).__name__


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
