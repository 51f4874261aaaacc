"""Attack scripts (issue 17): what a faulty or hostile process on the host or LAN sends.

Each is a function over a :class:`haptic.common.wire.link.Link` (or raw Zenoh puts) so tests can run
them against the real programs; ``python -m tests.helpers.attacks --help`` runs them by hand.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable

import zenoh

from haptic.common.wire.link import Link
from haptic.common.wire.messages import (
    KIND_HANDLE,
    KIND_TOOL,
    SCHEMA_VERSION,
    Flags,
    HandleState,
    ToolState,
    encode,
)


def steady_master(link: Link, duration_s: float, force_N: tuple[float, float] = (1.0, 0.0),
                  position_m: tuple[float, float] = (0.0, 0.0), period_s: float = 0.001,
                  inject: Callable[[int], tuple[float, float] | None] | None = None,
                  follow: bool = True) -> int:
    """A well-behaved master (forces enabled; the handle at ``position_m``, or with
    ``follow`` where the slave's tool is, as a handle coupled to it would be, Ah1 = 1) for
    ``duration_s``, one message per ``period_s``. ``inject(i)`` may return a forged force
    (N) to send in message ``i`` of the same sender instead (a faulty master, or a forger
    that has the session). Returns the number of forged messages sent."""
    forged = 0
    deadline = time.monotonic() + duration_s
    i = 0
    next_s = time.monotonic()
    while time.monotonic() < deadline:
        link.poll()
        if follow and isinstance(link.latest, ToolState):
            position_m = link.latest.tool_position_m
        force = inject(i) if inject is not None else None
        if force is not None:
            forged += 1
        link.send_handle(force if force is not None else force_N, position_m,
                         Flags.FORCES_ENABLED)
        i += 1
        next_s += period_s
        delay = next_s - time.monotonic()
        if delay > 0:
            time.sleep(delay)
    return forged


def steady_slave(link: Link, duration_s: float, period_s: float = 0.001,
                 inject: Callable[[int], tuple[float, float] | None] | None = None) -> int:
    """A well-behaved slave (ready, no contact, its tool where the master's handle is, Ah1 =
    1) for ``duration_s``, one message per ``period_s``. ``inject(i)`` may return a tool
    position offset (m) to send in message ``i`` of the same sender instead (a faulty slave,
    or a forger that has the session: the tool "jumps"). Returns the number of jumped
    messages sent."""
    forged = 0
    deadline = time.monotonic() + duration_s
    i = 0
    next_s = time.monotonic()
    position_m = (0.0, 0.0)
    while time.monotonic() < deadline:
        link.poll()
        if isinstance(link.latest, HandleState):
            position_m = link.latest.handle_position_m
        offset = inject(i) if inject is not None else None
        sent = position_m
        if offset is not None:
            forged += 1
            sent = (position_m[0] + offset[0], position_m[1] + offset[1])
        link.send_tool((0.0, 0.0), sent, (0.0, 0.0), 0.0, 0.0, Flags.FORCES_ENABLED)
        i += 1
        next_s += period_s
        delay = next_s - time.monotonic()
        if delay > 0:
            time.sleep(delay)
    return forged


def forged_payload(kind: int, epoch: int, seq: int, force_N: float,
                   send_time_ns: int | None = None, version: int = SCHEMA_VERSION) -> bytes:
    """An unauthenticated message of ``kind`` in the wire format (a stranger's forgery):
    ``force_N`` on x of the handle or tool force."""
    now = time.time_ns() if send_time_ns is None else send_time_ns
    flags = Flags.FORCES_ENABLED
    if kind == KIND_HANDLE:
        message = HandleState(epoch, seq, now, flags, (force_N, 0.0), (0.0, 0.0))
    else:
        message = ToolState(epoch, seq, now, flags, (force_N, 0.0), (0.0, 0.0), (0.0, 0.0),
                            0.0, 0.0)
    payload = encode(message)
    if version != SCHEMA_VERSION:
        payload = payload[:1] + bytes([version]) + payload[2:]
    return payload


def flood(session: zenoh.Session, key: str, rate_hz: float, duration_s: float,
          payload: Callable[[int], bytes]) -> int:
    """Put ``payload(i)`` on ``key`` at about ``rate_hz`` for ``duration_s``; returns the
    number sent. Bursts of puts between short sleeps, so high rates are reachable."""
    publisher = session.declare_publisher(key, congestion_control=zenoh.CongestionControl.DROP,
                                          express=True)
    sent = 0
    start = time.monotonic()
    try:
        while (elapsed := time.monotonic() - start) < duration_s:
            due = int(elapsed * rate_hz)
            while sent < due:
                publisher.put(payload(sent))
                sent += 1
            time.sleep(0.0005)
    finally:
        publisher.undeclare()
    return sent


def main() -> None:
    parser = argparse.ArgumentParser(description="Attack a running link (issue 17).")
    parser.add_argument("attack", choices=("forge-tool", "forge-handle", "junk"))
    parser.add_argument("--connect", required=True, help="a Zenoh endpoint of the link")
    parser.add_argument("--key-prefix", default="haptic/rig-1")
    parser.add_argument("--rate", type=float, default=1000.0)
    parser.add_argument("--duration", type=float, default=3.0)
    parser.add_argument("--force", type=float, default=1e9)
    parser.add_argument("--victim", choices=("master", "slave"), default="master",
                        help="junk: whose receive key to flood (master: <prefix>/tool)")
    args = parser.parse_args()
    config = zenoh.Config()
    config.insert_json5("connect/endpoints", json.dumps([args.connect]))
    config.insert_json5("scouting/multicast/enabled", "false")
    with zenoh.open(config) as session:
        time.sleep(0.5)  # let the victims' subscriptions reach this session
        # 0 when the victims admit only authenticated transports (a session key)
        peers = len(list(session.info.peers_zid()))
        if args.attack == "junk":
            key = "tool" if args.victim == "master" else "handle"
            sent = flood(session, f"{args.key_prefix}/{key}", args.rate, args.duration,
                         lambda i: bytes(50))
        else:
            kind = KIND_TOOL if args.attack == "forge-tool" else KIND_HANDLE
            key = f"{args.key_prefix}/{'tool' if kind == KIND_TOOL else 'handle'}"
            sent = flood(session, key, args.rate, args.duration,
                         lambda i: forged_payload(kind, 1234 + i, i, args.force))
    print(f"peers {peers} sent {sent}")


if __name__ == "__main__":
    main()
