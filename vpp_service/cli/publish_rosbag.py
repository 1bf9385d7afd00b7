"""``vpp-service publish --rosbag PATH``: replay a rosbag2 bag onto rmw_zenoh topics, like ``ros2 bag play``.

Every topic of the bag whose type hash is known (the standard ROS 2 types of the
``rosbags`` Jazzy type store) gets a publisher, a liveliness token and the 33-byte
attachment on every sample; other topics are skipped and listed. Messages go out at
the recorded timing times ``--rosbag-rate`` (0 = as fast as possible), ``--loop``
replays forever, ``--count`` caps the number of messages.

A damaged bag plays every readable message; each damaged place is printed to stderr
with its cause and where it is, and the closing JSON line counts them by cause
(``damaged``; the first pass only). A bag of which nothing can be read is an error.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import threading
import time
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from vpp_service.service.config import ZenohSection


def play(args: argparse.Namespace) -> int:
    """Replay ``args.rosbag`` until its end (or ``--count``, or SIGINT/SIGTERM)."""
    from vpp_service.service.config import ZenohSection
    from vpp_service.transport.ros2.bag import bag_topics
    from vpp_service.transport.ros2.messages import typestore

    rate = float(args.rosbag_rate)
    if not 0 <= rate <= 1000:
        raise ValueError(f"--rosbag-rate: must be in [0, 1000], got {rate}")
    topics = bag_topics(args.rosbag)
    hashes: dict[str, str] = {}
    skipped: list[str] = []
    for topic, ros_type in topics.items():
        try:
            hashes[topic] = typestore().hash_rihs01(ros_type)
        except Exception:  # noqa: BLE001 - rosbags raises KeyError/TypesysError for types its store lacks
            skipped.append(topic)
    damaged: dict[str, int] = {}
    zsec = ZenohSection(
        mode="peer", listen=list(args.listen), connect=list(args.connect), multicast_scouting=args.multicast_scouting
    )
    stop = threading.Event()
    old = {s: signal.signal(s, lambda *_: stop.set()) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        sent, elapsed = _replay(args, zsec, pubs_for=hashes, topics=topics, stop=stop, damaged=damaged)
    finally:
        for s, h in old.items():
            signal.signal(s, h)
    line = {"sent": sent, "seconds": round(elapsed, 3), "skipped_topics": skipped, "damaged": damaged}
    print(json.dumps(line), file=sys.stdout)
    return 0


def _replay(
    args: argparse.Namespace,
    zsec: ZenohSection,
    *,
    pubs_for: dict[str, str],
    topics: dict[str, str],
    stop: threading.Event,
    damaged: dict[str, int],
) -> tuple[int, float]:
    """Publish the bag's messages of the topics in ``pubs_for`` (topic -> type hash); returns (sent, seconds).

    Each damaged place of the bag is printed to stderr and counted by cause in ``damaged`` (first pass).
    """
    from vpp_service.service.app import open_session
    from vpp_service.transport.ros2.bag import read_bag
    from vpp_service.transport.ros2.bag_damage import BagDamage, ignore_damage
    from vpp_service.transport.ros2.keys import RELIABLE_KEEP_ALL
    from vpp_service.transport.ros2.node import RosNode, RosPublisher

    def count_damage(damage: BagDamage) -> None:
        damaged[damage.cause] = damaged.get(damage.cause, 0) + 1
        print(f"vpp-service publish: damaged bag: {damage}", file=sys.stderr)

    rate = float(args.rosbag_rate)
    hashes = pubs_for
    sent = 0
    with open_session(zsec) as session:
        if session is None:  # zsec is enabled: open_session always opens one
            raise ValueError("publish --rosbag: no zenoh session")
        node = RosNode(session, args.ros_domain, "/", "vpp_bag_player")
        node.open()
        # reliable + keep all: congestion control BLOCK (rmw_zenoh's mapping), no message of the bag lost
        pubs: dict[str, RosPublisher] = {
            t: node.publisher(t, topics[t], RELIABLE_KEEP_ALL, hash_=h) for t, h in hashes.items()
        }
        deadline = time.monotonic() + max(0.0, args.wait_subscriber)
        while time.monotonic() < deadline and not stop.is_set() and not any(p.matching for p in pubs.values()):
            time.sleep(0.02)
        t0 = time.monotonic()
        first = True
        while not stop.is_set():
            start_wall, start_bag = time.monotonic(), None
            for m in read_bag(args.rosbag, set(pubs), count_damage if first else ignore_damage):
                start_bag = m.log_time_ns if start_bag is None else start_bag
                if rate > 0:
                    delay = start_wall + (m.log_time_ns - start_bag) / 1e9 / rate - time.monotonic()
                    if delay > 0 and stop.wait(delay):
                        break
                if stop.is_set() or (args.count and sent >= args.count):
                    break
                pubs[m.topic].put(bytes(m.data))
                sent += 1
            first = False
            if not args.loop or (args.count and sent >= args.count):
                break
        elapsed = time.monotonic() - t0
        node.close()
    return sent, elapsed


__all__ = ["play"]
