"""A Zenoh router in Python, for client-mode deployments (zenohd is not on PyPI).

    python deploy/zenoh_router.py --listen tcp/0.0.0.0:7447 [--zenoh-set KEY=VALUE ...]

Runs until SIGINT or SIGTERM, then closes its session and exits 0.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import threading

import zenoh


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--listen", action="append", default=[], metavar="ENDPOINT",
                        help="endpoint to listen on (repeatable; default tcp/0.0.0.0:7447)")
    parser.add_argument("--zenoh-set", action="append", default=[], metavar="KEY=VALUE",
                        help="a Zenoh configuration override, VALUE in json5")
    args = parser.parse_args(argv)
    config = zenoh.Config()
    config.insert_json5("mode", '"router"')
    config.insert_json5("listen/endpoints", json.dumps(args.listen or ["tcp/0.0.0.0:7447"]))
    for item in args.zenoh_set:
        key, _, value = item.partition("=")
        config.insert_json5(key, value)
    stop = threading.Event()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: stop.set())
    with zenoh.open(config) as session:
        print(f"zenoh router {session.zid()} listening on {args.listen or ['tcp/0.0.0.0:7447']}",
              file=sys.stderr)
        while not stop.wait(0.2):
            pass
    return 0


if __name__ == "__main__":
    sys.exit(main())
