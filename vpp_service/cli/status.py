"""``vpp-service status``: query a running service's ``@status`` and print the JSON reply."""

from __future__ import annotations

import argparse
import json
from typing import Any


def add_parser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register the ``status`` sub-command."""
    p = subparsers.add_parser("status", help="query a running service's @status (JSON)", description=__doc__)
    p.add_argument("--rig", default="*", help="rig name ('*' = every rig)")
    p.add_argument("--prefix", default="vpp")
    p.add_argument(
        "--connect",
        action="append",
        default=[],
        metavar="ENDPOINT",
        help="endpoint of the service (default tcp/127.0.0.1:7447)",
    )
    p.add_argument("--multicast-scouting", action="store_true", help="enable multicast discovery")
    p.add_argument("--timeout", type=float, default=3.0, help="seconds to wait for replies")
    p.set_defaults(func=main)


def query_status(
    connect: list[str], prefix: str = "vpp", rig: str = "*", timeout: float = 3.0, multicast_scouting: bool = False
) -> dict[str, Any]:
    """Query ``<prefix>/<rig>/@status``; returns ``{key: reply JSON}`` (each reply a decoded JSON object).

    Raises
    ------
    ValueError
        Bad ``timeout``; a reply that is not JSON.
    """
    from vpp_service.service.app import zenoh_session
    from vpp_service.service.config import ZenohSection

    if not timeout > 0:
        raise ValueError(f"timeout must be > 0, got {timeout}")
    zsec = ZenohSection(mode="peer", listen=[], connect=list(connect), multicast_scouting=multicast_scouting)
    out: dict[str, Any] = {}
    with zenoh_session(zsec) as session:
        for reply in session.get(f"{prefix}/{rig}/@status", timeout=timeout):
            if reply.ok is not None:
                try:
                    out[str(reply.ok.key_expr)] = json.loads(reply.ok.payload.to_string())
                except json.JSONDecodeError as exc:
                    raise ValueError(f"{reply.ok.key_expr}: reply is not JSON: {exc}") from None
    return out


def main(args: argparse.Namespace) -> int:
    """Print the replies as JSON; exit 1 when no service answered."""
    replies = query_status(
        args.connect or ["tcp/127.0.0.1:7447"], args.prefix, args.rig, args.timeout, args.multicast_scouting
    )
    print(json.dumps(replies, indent=2))
    return 0 if replies else 1
