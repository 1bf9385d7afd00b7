"""vpp-service status: query running services' @status and print the replies as JSON.

The output maps each service's own key (<prefix>/<rig>/@status) to its status,
so --rig '*' lists every rig that replied, one entry each. When no service replies within
--timeout it says so on stderr and exits 1; when the endpoint cannot be reached
it says it could not connect (exit 1).

Which services reply: every service reachable through a Zenoh router, or, in a
router-less mesh of peers, the services this command's session links to (the one
at --connect, and the peers gossip leads it to that listen on an endpoint). A
service that only connects out to another peer and listens nowhere cannot be
reached this way: query it at its own endpoint, or run a router.
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from vpp_service.cli.help import HelpFormatter, plain


def add_parser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register the ``status`` sub-command."""
    from vpp_service.service.config import ENDPOINT_ENV, default_endpoint

    p = subparsers.add_parser(
        "status",
        help="query running services' @status (JSON)",
        description=plain(__doc__),
        formatter_class=HelpFormatter,
    )
    p.add_argument("--rig", default="*", help="rig name ('*' = every rig)")
    p.add_argument("--prefix", default="vpp", help="Zenoh key prefix of the service")
    p.add_argument(
        "--connect",
        action="append",
        default=[],
        metavar="ENDPOINT",
        help=f"endpoint of the service (repeatable; default {default_endpoint()}, or ${ENDPOINT_ENV})",
    )
    p.add_argument("--multicast-scouting", action="store_true", help="enable multicast discovery")
    p.add_argument("--timeout", type=float, default=3.0, help="seconds to wait for replies")
    p.set_defaults(func=main)


def query_status(
    connect: list[str],
    prefix: str = "vpp",
    rig: str = "*",
    timeout: float = 3.0,
    multicast_scouting: bool = False,
    *,
    unreachable_error: bool = False,
) -> dict[str, Any]:
    """Query ``<prefix>/<rig>/@status``; returns ``{service key: reply JSON}``, one entry per rig that replied.

    Raises
    ------
    ValueError
        Bad ``timeout``; a reply that is not JSON.
    ConnectionError
        With ``unreachable_error``: none of the ``connect`` endpoints could be reached (nothing
        listens there); without it such a query just has no reply.
    """
    from vpp_service.service.app import has_link, zenoh_session
    from vpp_service.service.config import ZenohSection

    if not timeout > 0:
        raise ValueError(f"--timeout: must be > 0, got {timeout}")
    zsec = ZenohSection(mode="peer", listen=[], connect=list(connect), multicast_scouting=multicast_scouting)
    out: dict[str, Any] = {}
    with zenoh_session(zsec) as session:
        for reply in session.get(f"{prefix}/{rig}/@status", timeout=timeout):
            if reply.ok is not None:
                try:
                    out[str(reply.ok.key_expr)] = json.loads(reply.ok.payload.to_string())
                except json.JSONDecodeError as exc:
                    raise ValueError(f"{reply.ok.key_expr}: reply is not JSON: {exc}") from None
        if unreachable_error and not out and connect and not has_link(session):
            raise ConnectionError(f"could not connect to {', '.join(connect)} (nothing replies there)")
    return dict(sorted(out.items()))


def main(args: argparse.Namespace) -> int:
    """Print the replies as JSON; exit 1 with a message when no service replied."""
    from vpp_service.service.config import default_endpoint

    connect = args.connect or [default_endpoint()]
    try:
        replies = query_status(
            connect, args.prefix, args.rig, args.timeout, args.multicast_scouting, unreachable_error=True
        )
    except ConnectionError as exc:
        print(f"vpp-service status: {exc}", file=sys.stderr)
        return 1
    if not replies:
        print(
            f"vpp-service status: no service answered on {args.prefix}/{args.rig}/@status "
            f"within {args.timeout:g} s (connected to {', '.join(connect)})",
            file=sys.stderr,
        )
        return 1
    print(json.dumps(replies, indent=2))
    return 0
