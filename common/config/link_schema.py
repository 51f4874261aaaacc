"""The ``[link]`` table's schema (plain data): transport, watchdog, security and each side's
endpoints and injection. :mod:`haptic.common.wire.link_config` turns the validated table into
a :class:`~haptic.common.wire.link_config.LinkConfig`.
"""

from __future__ import annotations

from haptic.common.config.fields import Field, Schema
from haptic.common.model.delay_profile import delay_profile_problem

#: How injected jitter is drawn within [0, jitter_s].
JITTER_DISTRIBUTIONS = ("uniform", "normal", "exponential")

SIDES = ("master", "slave")
MODES = ("peer", "client")
CONGESTION_CONTROLS = ("drop", "block")
_PROTOCOLS = ("tcp", "udp", "tls", "quic", "ws", "unixsock-stream", "serial", "unixpipe")


def split_endpoints(text: str) -> tuple[str, ...]:
    """``"a, b"`` -> ``("a", "b")``; empty text -> ``()``."""
    return tuple(part.strip() for part in text.split(",") if part.strip())


def endpoint_problem(endpoint: str) -> str | None:
    """Why ``endpoint`` is not a zenoh locator ``proto/address``, or ``None``."""
    proto, slash, address = endpoint.partition("/")
    if not slash or not address:
        return f"endpoint {endpoint!r} is not of the form proto/address (e.g. tcp/127.0.0.1:7447)"
    if proto not in _PROTOCOLS:
        return f"endpoint {endpoint!r} has unknown protocol {proto!r}"
    return None


def _endpoints_check(text: str) -> str | None:
    for endpoint in split_endpoints(text):
        problem = endpoint_problem(endpoint)
        if problem:
            return problem
    return None


def key_prefix_problem(text: str) -> str | None:
    if not text or text.startswith("/") or text.endswith("/"):
        return "must be a non-empty key expression without leading or trailing '/'"
    if any(c in text for c in "*$?#") or "//" in text:
        return "must be a plain key expression (no wildcards '*', '$', '?', '#' or '//')"
    return None


INJECTION_SCHEMA: Schema = {
    "delay_s": Field("float", "One-way delay injected on receive, s.", minimum=0.0, maximum=10.0),
    "jitter_s": Field(
        "float", "Bound of the extra random delay on top of delay_s, s.", minimum=0.0,
        maximum=10.0,
    ),
    "jitter_distribution": Field(
        "str", "Jitter distribution within [0, jitter_s].", choices=JITTER_DISTRIBUTIONS
    ),
    "preserve_order": Field("bool", "Jitter never reorders messages (a FIFO link like TCP)."),
    "loss_probability": Field(
        "float", "Independent loss probability per message.", minimum=0.0, maximum=1.0
    ),
    "burst_enter_probability": Field(
        "float", "Gilbert-Elliott good -> bad probability per message (0: no bursts).",
        minimum=0.0, maximum=1.0,
    ),
    "burst_exit_probability": Field(
        "float", "Gilbert-Elliott bad -> good probability per message (1/mean burst length).",
        minimum=0.0, maximum=1.0, exclusive_minimum=True,
    ),
    "burst_loss_probability": Field(
        "float", "Loss probability per message in the bad state.", minimum=0.0, maximum=1.0
    ),
    "seed": Field("int", "Seed of this side's injected jitter and loss.", minimum=0),
    "delay_profile": Field(
        "str", "One-way delay over time added to delay_s, e.g. 'step 0:0.002 3:0.040' or "
        "'linear 0:0.002 5:0.040' (time since the peer's first message, s : delay, s); "
        "empty: none.", check=delay_profile_problem,
    ),
}


def _side_schema(doc: str) -> Schema:
    return {
        "endpoints": {
            "listen": Field(
                "str", f"Endpoints the {doc} listens on, comma separated.",
                check=_endpoints_check,
            ),
            "connect": Field(
                "str", f"Endpoints the {doc} connects to (the router in client mode).",
                check=_endpoints_check,
            ),
        },
        "injection": INJECTION_SCHEMA,
    }


TRANSPORT_SCHEMA: Schema = {
    "mode": Field("str", "Zenoh mode: peer, or client of a router.", choices=MODES),
    "key_prefix": Field("str", "Key expression prefix of the rig.", check=key_prefix_problem),
    "multicast_scouting": Field("bool", "Discover peers by UDP multicast scouting."),
    "express": Field("bool", "Send every message at once, without batching."),
    "congestion_control": Field(
        "str", "drop (never block the loop) or block.", choices=CONGESTION_CONTROLS
    ),
    "tx_queue_size_real_time": Field(
        "int", "Zenoh transmit queue size of the real-time priority, batches.", minimum=1,
        maximum=1024,
    ),
    "receive_queue_capacity": Field(
        "int", "Samples the receive ring holds between two polls.", minimum=1, maximum=1_000_000
    ),
    "lease_s": Field(
        "float", "Zenoh link lease: a silent peer is declared gone after this, s.",
        minimum=0.001, maximum=3600.0,
    ),
}

WATCHDOG_SCHEMA: Schema = {
    "max_message_age_s": Field(
        "float", "No fresh peer message for this long -> safe state, s.",
        minimum=0.0, exclusive_minimum=True, maximum=60.0,
    ),
    "stale_after_s": Field(
        "float", "Drop a message older than this at arrival (beyond the injected delay), s.",
        minimum=0.0, exclusive_minimum=True, maximum=60.0,
    ),
    "resync_messages": Field(
        "int", "Fresh messages in a row needed after start-up or a trip before resync.",
        minimum=1, maximum=1_000_000,
    ),
}

SECURITY_SCHEMA: Schema = {
    "session_key_file": Field(
        "str", "Authenticated sessions (common/wire/auth.py): a file with the pre-shared key (64 "
        "hex digits, mode 600); both sides must have the same. Empty: no authentication "
        "(one trusted host only).",
    ),
    "transport_auth": Field(
        "bool", "With a session key in peer mode, Zenoh admits only transports that "
        "authenticate with credentials derived from it: a process without the key cannot "
        "join, read or flood the session (common/wire/transport_auth.py).",
    ),
    "insecure": Field(
        "bool", "Protected mode off (common/wire/protected_mode.py): let a session that "
        "listens on or connects to a non-loopback address (or scouts by multicast) run with "
        "neither a session key nor mutual TLS, so anyone who reaches it can drive the handle "
        "and the tool; the status line and summary then say UNAUTHENTICATED. false (the "
        "default): such a start is refused (exit 2). Loopback never needs it.",
    ),
    "max_samples_per_poll": Field(
        "int", "Flood bound: samples one poll takes from the receive ring at most; the rest "
        "wait for the next tick (a flood costs the loop a bounded time per tick).",
        minimum=1, maximum=1_000_000,
    ),
}

# Only tables at this level and in the side tables: a file may override one of them (say
# [link.slave.endpoints]) without repeating the others (see haptic.common.config's rules).
LINK_SCHEMA: Schema = {
    "transport": TRANSPORT_SCHEMA,
    "watchdog": WATCHDOG_SCHEMA,
    "security": SECURITY_SCHEMA,
    "master": _side_schema("master"),
    "slave": _side_schema("slave"),
}
