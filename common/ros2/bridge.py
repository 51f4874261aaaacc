"""The ROS 2 bridge process: a program's figures from its shared-memory feed to rmw_zenoh.

Started and ended by the program (:class:`~haptic.common.ros2.bridge_handle.Ros2Bridge`),
never by hand: ``python -m haptic.common.ros2.bridge --feed PATH --side master ...``. It
runs a :class:`~haptic.common.ros2.publisher.Ros2Publisher` (its own Zenoh session in
client mode to the router, the liveliness tokens, the topics) fed from the feed
(:mod:`haptic.common.ros2.feed`) at the publish rate, and writes the publisher's counters
back for the program's summary. It runs under SCHED_IDLE where the platform has it (only on
CPU time the program's threads leave; it inherits the program's CPUs for threads other than
the loop). It ends on SIGTERM or SIGINT (tokens withdrawn, session
closed, exit 0), and by itself when the program that started it is gone (removing the feed
file, which the program would have removed).
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
from pathlib import Path
from typing import Any

from haptic.common.ros2.feed import FeedReader
from haptic.common.ros2.publisher import Ros2Publisher
from haptic.common.ros2.settings import Ros2Settings


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m haptic.common.ros2.bridge",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--feed", type=Path, required=True, help="the feed file")
    parser.add_argument("--side", choices=("master", "slave"), required=True)
    parser.add_argument("--domain-id", type=int, required=True, help="ROS domain id")
    parser.add_argument("--namespace", required=True, help="the nodes' namespace")
    parser.add_argument("--endpoint", required=True, help="the router's Zenoh endpoint")
    parser.add_argument("--rate", type=float, required=True, help="state topics' rate, Hz")
    parser.add_argument("--topics", required=True, help="topic groups, comma-separated")
    parser.add_argument("--clay-shape", type=int, nargs=2, metavar=("ROWS", "COLUMNS"),
                        help="the clay height map's shape, cells (none: no clay)")
    parser.add_argument("--clay-ranges", type=float, nargs=4, metavar=("X0", "X1", "Y0", "Y1"),
                        help="the clay map's extent, m")
    parser.add_argument("--parent-pid", type=int, required=True,
                        help="end when this process is gone")
    parser.add_argument("--say-prefix", default="ros2: ", help="prefix of the lines said")
    return parser


def _batch_scheduling() -> None:
    """SCHED_IDLE for this process and the threads it starts (best effort): it runs only
    on CPU time nothing else of the program's wants, so it never takes a time slice from
    a thread of the program (a Zenoh thread holding the program's GIL, the loop waiting)."""
    if hasattr(os, "sched_setscheduler") and hasattr(os, "SCHED_IDLE"):
        try:
            os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
        except OSError:
            pass


def serve(args: argparse.Namespace, stop: threading.Event) -> int:
    """Feed the publisher from the feed until ``stop`` or the parent is gone; returns 0."""
    settings = Ros2Settings(args.domain_id, args.namespace, args.endpoint, args.rate,
                            frozenset(part.strip() for part in args.topics.split(",")))
    clay_shape = tuple(args.clay_shape) if args.clay_shape else None
    reader = FeedReader(args.feed, clay_shape)  # type: ignore[arg-type]
    counts = {"loop": (0, 0)}
    clay_ranges = ((args.clay_ranges[0], args.clay_ranges[1]),
                   (args.clay_ranges[2], args.clay_ranges[3])) if args.clay_ranges else None
    publisher = Ros2Publisher(
        settings, args.side, say=lambda text: print(f"{args.say_prefix}{text}",
                                                     file=sys.stderr, flush=True),
        loop_counts=lambda: counts["loop"],
        clay_source=reader.clay if clay_shape is not None else None,
        clay_ranges=clay_ranges if clay_shape is not None else None).start()
    period_s = 1.0 / settings.publish_rate_hz
    try:
        while not stop.is_set() and os.getppid() == args.parent_pid:
            state = reader.state()
            if state is not None:
                counts["loop"] = (int(state["loop_ticks"]), int(state["loop_overruns"]))
                publisher.offer_state(state)
            status = reader.status()
            if status is not None:
                publisher.offer_status(status)
            reader.write_counters(_counters(publisher))
            stop.wait(period_s)
    finally:
        publisher.stop()
        reader.write_counters(_counters(publisher))
        reader.close()
        if os.getppid() != args.parent_pid:  # the program is gone: nobody else removes it
            args.feed.unlink(missing_ok=True)
    return 0


def _counters(publisher: Ros2Publisher) -> dict[str, Any]:
    figures = publisher.figures
    return {"published": figures["ros2_published"],
            "unwatched_skips": figures["ros2_unwatched_skips"],
            "open_failures": figures["ros2_open_failures"],
            "publish_errors": figures["ros2_publish_errors"],
            "connected": int(figures["ros2_connected"])}


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    _batch_scheduling()
    stop = threading.Event()
    for number in (signal.SIGTERM, signal.SIGINT):
        signal.signal(number, lambda *_: stop.set())
    return serve(args, stop)


if __name__ == "__main__":
    sys.exit(main())
