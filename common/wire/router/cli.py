"""``haptic-router``: a Zenoh router in Python for client-mode deployments.

zenohd (the Zenoh project's router binary) is not a PyPI package; this runs the same router
from the eclipse-zenoh wheel, with the same json5 configuration files (deploy/zenoh/), so
either can serve the deployment::

    haptic-router --zenoh-config deploy/zenoh/router.json5
    haptic-router --listen tcp/0.0.0.0:7447 [--zenoh-set KEY=VALUE ...]

``--zenoh-config`` is loaded first, then ``--listen`` (replaces ``listen/endpoints``), then every
``--zenoh-set`` (json5 value). Mode is always ``router``. Runs until SIGINT or SIGTERM, then
closes its session and exits 0; a configuration Zenoh rejects exits 2 with one line.

Protected mode (common/wire/protected_mode.py): a router that listens on or connects to a
non-loopback address without mutual TLS (deploy/zenoh/router.json5) exits 2 with one line
unless ``--insecure`` is given; it then says ``UNAUTHENTICATED (--insecure)`` in its
listening line. A router has no session key of its own: the programs' keys authenticate their
messages end to end through it, but without mutual TLS anyone who reaches it can join, read
the positions and forces and flood the keys.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import threading

import zenoh

from haptic.common.config import ConfigError
from haptic.common.wire.protected_mode import require_protection

DEFAULT_LISTEN = "tcp/0.0.0.0:7447"
#: The ways out of the protected mode's refusal, for a router.
ROUTER_WAYS_OUT = ("give it mutual TLS (--zenoh-config FILE with transport/link/tls "
                   "enable_mtls, deploy/zenoh/router.json5), or say --insecure to relay "
                   "unauthenticated")


def router_config(
    config_file: str | None, listen: list[str], overrides: list[str]
) -> zenoh.Config:
    """The router's Zenoh configuration: ``config_file`` (json5), then ``listen`` endpoints
    (when given, or :data:`DEFAULT_LISTEN` without a file), then the ``KEY=VALUE``
    ``overrides``. Raises ``ValueError`` for a malformed override, zenoh's error otherwise."""
    config = zenoh.Config.from_file(config_file) if config_file else zenoh.Config()
    config.insert_json5("mode", '"router"')
    if listen or not config_file:
        config.insert_json5("listen/endpoints", json.dumps(listen or [DEFAULT_LISTEN]))
    for item in overrides:
        key, equals, value = item.partition("=")
        if not equals or not key.strip() or not value.strip():
            raise ValueError(f"--zenoh-set {item!r} is not KEY=VALUE")
        config.insert_json5(key.strip(), value.strip())
    return config


def main(argv: list[str] | None = None) -> int:
    # the docstring's first sentence, as plain text (common/runtime/console.py's
    # script_description is a layer above common/wire)
    parser = argparse.ArgumentParser(
        prog="haptic-router", allow_abbrev=False,
        description="A Zenoh router in Python for client-mode deployments.")
    parser.add_argument("--zenoh-config", metavar="FILE",
                        help="Zenoh json5 configuration file (as --zenoh-config of the programs)")
    parser.add_argument(
        "--listen", action="append", default=[], metavar="ENDPOINT",
        help=f"endpoint to listen on (repeatable; default {DEFAULT_LISTEN} without --zenoh-config)",
    )
    parser.add_argument(
        "--zenoh-set", action="append", default=[], metavar="KEY=VALUE",
        help="a Zenoh configuration override, VALUE in json5, applied last (repeatable)",
    )
    parser.add_argument(
        "--insecure", action="store_true",
        help="listen on a non-loopback address without mutual TLS (refused without it, exit 2): "
        "anyone who reaches the router can join the session",
    )
    args = parser.parse_args(argv)
    try:
        config = router_config(args.zenoh_config, args.listen, args.zenoh_set)
    except Exception as error:  # noqa: BLE001 - zenoh raises its own ZError
        print(f"haptic-router: {' '.join(str(error).split())[:240]}", file=sys.stderr)
        return 2
    try:
        marker = require_protection(config, False, args.insecure, ROUTER_WAYS_OUT).marker
    except ConfigError as error:
        print(f"haptic-router: {str(error).removeprefix(f'{error.key}: ')}", file=sys.stderr)
        return 2
    stop = threading.Event()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: stop.set())
    try:
        session = zenoh.open(config)
    except Exception as error:  # noqa: BLE001
        print(f"haptic-router: cannot start: {' '.join(str(error).split())[:240]}",
              file=sys.stderr)
        return 1
    with session:
        listening = config.get_json("listen/endpoints")
        print(f"zenoh router {session.zid()} listening on {listening}"
              + (f" {marker}" if marker else ""), file=sys.stderr, flush=True)
        while not stop.wait(0.2):
            pass
    return 0


if __name__ == "__main__":
    sys.exit(main())
