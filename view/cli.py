"""``haptic-view [--port N] [--config FILE]``: the live view of a run in the browser.

Joins the run's Zenoh session (by default the way the slave does: it connects to the master's
listener, ``[link.slave.endpoints]``; ``--connect`` replaces it) and serves the page on
``http://127.0.0.1:PORT/`` until SIGINT or SIGTERM. Open that address in a browser.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence

import zenoh

from haptic.common.config import exit_on_config_error, load_config, override
from haptic.common.config.link_schema import split_endpoints
from haptic.common.runtime.console import script_description
from haptic.common.runtime.failures import exit_on_link_error
from haptic.common.runtime.runner import StopSignals
from haptic.common.wire.errors import LinkOpenError
from haptic.common.wire.link import zenoh_config
from haptic.common.wire.link_config import LinkConfig, link_config_from
from haptic.common.wire.protected_mode import require_protection
from haptic.view.server import DEFAULT_MAX_RATE_HZ, ViewServer
from haptic.view.source import ZenohSource
from haptic.view.state import ViewState

#: The ways out of the protected mode's refusal, for the view (common/wire/protected_mode.py).
VIEW_WAYS_OUT = ("give it the programs' --session-key FILE ([link.security] session_key_file), "
                 "or say --insecure ([link.security] insecure = true) to watch unauthenticated")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="haptic-view", description=script_description(__doc__),
                                     allow_abbrev=False)
    parser.add_argument("--port", metavar="N", type=int, default=8765,
                        help="HTTP port on 127.0.0.1 (default 8765; 0: any free port)")
    parser.add_argument("--config", metavar="FILE", help="TOML configuration (over the defaults)")
    parser.add_argument("--connect", metavar="ENDPOINT", action="append",
                        help="Zenoh endpoint to connect to (default: the slave's, "
                        "link.slave.endpoints.connect)")
    parser.add_argument("--key-prefix", metavar="PREFIX", help="key prefix of the rig")
    parser.add_argument("--session-key", metavar="FILE",
                        help="the programs' pre-shared key file (link.security."
                        "session_key_file): with one, they admit only transports that "
                        "authenticate with it, a viewer's too")
    parser.add_argument("--insecure", action="store_const", const=True, default=None,
                        help="connect beyond loopback without a session key "
                        "(link.security.insecure; refused without it, exit 2)")
    parser.add_argument("--rate", metavar="HZ", type=float, default=DEFAULT_MAX_RATE_HZ,
                        help=f"display rate: Zenoh polls and frames per second per browser "
                        f"(default {DEFAULT_MAX_RATE_HZ:g})")
    parser.add_argument("--no-backoff", dest="backoff", action="store_false",
                        help="keep the frame rate while the loops overrun (by default it "
                        "falls to as little as a sixteenth until they hold their period)")
    return parser


def view_link_config(config: dict, connect: Sequence[str] | None) -> LinkConfig:
    """The view's link settings: the slave's transport settings and session key, connecting
    where the slave connects (or to ``connect``) and listening on a free loopback port so the
    peers' gossip can reach it."""
    changes = {"listen": ("tcp/127.0.0.1:0",)}
    if connect:
        changes["connect"] = tuple(e for item in connect for e in split_endpoints(item))
    return link_config_from(config, "slave", **changes)


def view_zenoh_config(config: dict, connect: Sequence[str] | None) -> zenoh.Config:
    """The view's Zenoh configuration (:func:`view_link_config`)."""
    return zenoh_config(view_link_config(config, connect))


def _view_server(state: ViewState, port: int, rate_hz: float) -> ViewServer:
    """The HTTP server; a port in use is a :class:`LinkOpenError` (one line, exit 4)."""
    try:
        return ViewServer(state, port, max_rate_hz=rate_hz)
    except OSError as error:
        raise LinkOpenError(f"cannot serve HTTP on port {port}: {error.strerror}") from None


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point: 0 after SIGINT/SIGTERM; 2 for a configuration error, a session beyond
    loopback without a session key and without ``--insecure`` among them; 4 when the Zenoh
    session or the HTTP port cannot be opened (one line)."""
    args = build_parser().parse_args(argv)
    zenoh.init_log_from_env_or("error")
    with exit_on_config_error():
        config = load_config(args.config)
        if args.key_prefix is not None:
            config = override(config, "link.transport.key_prefix", args.key_prefix)
        if not args.rate > 0.0:
            from haptic.common.config import ConfigError

            raise ConfigError("--rate", f"must be > 0 Hz (got {args.rate})")
        if args.session_key is not None:
            config = override(config, "link.security.session_key_file", args.session_key)
        if args.insecure is not None:
            config = override(config, "link.security.insecure", args.insecure)
        link = view_link_config(config, args.connect)
        zconf = zenoh_config(link)
        marker = require_protection(zconf, link.session_key is not None, link.insecure,
                                    VIEW_WAYS_OUT).marker
    prefix = config["link"]["transport"]["key_prefix"]
    state = ViewState(backoff=args.backoff)
    with exit_on_link_error("haptic-view"), StopSignals() as signals, \
            ZenohSource(zconf, prefix, state, args.rate, transport_key=link.transport_key), \
            _view_server(state, args.port, args.rate) as server:
        print(f"haptic-view: {server.url} (keys {prefix}/...)" + (f" {marker}" if marker else ""),
              file=sys.stderr, flush=True)
        while not signals.requested:
            time.sleep(0.2)
    stats = server.stats()
    print(f"haptic-view: {stats['frames_sent']} frames sent, {stats['state_updates']} "
          f"updates", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
