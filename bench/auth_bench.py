"""Per-message cost of authenticated sessions (common/wire/auth.py): the sender's tag
(HMAC-SHA256 under the session key, 16 bytes), the receiver's verification, and the receive
path's decode-and-order with and without it, per message, in us. Target: <= 5 us per message
added on this machine (the tick is 542 us). Figures only; nothing is asserted.

Usage: ``python bench/auth_bench.py [--n N] [--json]``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import timeit

import numpy as np

from haptic.common.wire.auth import SessionAuth, decode_hello
from haptic.common.wire.injection import InjectionConfig
from haptic.common.wire.messages import KIND_TOOL, Flags, ToolState, encode
from haptic.common.wire.receive import ReceivePath


def _per_call_us(function, n: int) -> float:
    """The best of 5 runs of ``n`` calls, us per call."""
    return min(timeit.repeat(function, number=n, repeat=5)) / n * 1e6


def measure(n: int) -> dict[str, float]:
    psk = bytes(range(32))
    master, slave = SessionAuth(psk, "master", 1), SessionAuth(psk, "slave", 2)
    now = time.time_ns()
    master.accept_hello(decode_hello(slave.hello(now), psk), now)
    slave.accept_hello(decode_hello(master.hello(now), psk), now)
    messages = [encode(ToolState(2, seq, now + seq, Flags.FORCES_ENABLED, (1.0, 2.0),
                                 (0.01, 0.02), (0.1, 0.2), 0.5, 1e-6)) for seq in range(n)]
    tagged = [body + slave.tag(body) for body in messages]
    body = messages[0]
    plain = ReceivePath(KIND_TOOL, InjectionConfig(), np.random.default_rng(0), 10.0)
    authed = ReceivePath(KIND_TOOL, InjectionConfig(), np.random.default_rng(0), 10.0)
    authed.pin_epoch(2)
    plain_iter, authed_iter = iter(messages), iter(tagged)
    plain_us = _per_call_us(lambda: plain.accept(next(plain_iter), now), n // 5)
    authed_us = _per_call_us(lambda: authed.accept(master.verify(next(authed_iter)), now), n // 5)
    return {
        "tag_us": _per_call_us(lambda: slave.tag(body), n),
        "verify_us": _per_call_us(lambda: master.verify(tagged[0]), n),
        "receive_plain_us": plain_us,
        "receive_authenticated_us": authed_us,
        "added_per_message_us": _per_call_us(lambda: slave.tag(body), n)
        + _per_call_us(lambda: master.verify(tagged[0]), n),
        "target_us": 5.0,
    }


def main() -> int:
    parser = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=20000)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    result = measure(args.n)
    if args.json:
        print(json.dumps(result))
    else:
        for key, value in result.items():
            print(f"{key:28s} {value:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
