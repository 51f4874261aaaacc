"""Configuration of the link: the ``[link]`` TOML table and the :class:`LinkConfig` it becomes.

``[link.transport]`` and ``[link.watchdog]`` hold what both sides share (mode, key prefix, QoS;
watchdog ages); ``[link.master.endpoints]`` / ``[link.slave.endpoints]`` each side's endpoints,
and ``[link.master.injection]`` / ``[link.slave.injection]`` what that side's *receiving* link
injects (one way: the master's injection delays the tool's messages, the slave's the
handle's). Endpoints are zenoh locators (``tcp/127.0.0.1:7447``),
comma separated, empty for none.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

from haptic.common.config import ConfigError, Field, Schema
from haptic.common.delay_profile import delay_profile_problem, parse_delay_profile
from haptic.common.injection import JITTER_DISTRIBUTIONS, InjectionConfig

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


def _key_prefix_check(text: str) -> str | None:
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
    "key_prefix": Field("str", "Key expression prefix of the rig.", check=_key_prefix_check),
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
        "str", "Authenticated sessions (common/auth.py): a file with the pre-shared key (64 "
        "hex digits, mode 600); both sides must have the same. Empty: no authentication "
        "(one trusted host only).",
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


@dataclass(frozen=True)
class LinkConfig:
    """Everything :class:`haptic.common.link.Link` needs for one side.

    ``zenoh_config_file`` is loaded first, the settings here go on top, and ``zenoh_overrides``
    (``(key, json5 value)`` pairs, e.g. ``("transport/link/tx/lease", "2000")``) last.
    """

    side: str
    mode: str = "peer"
    key_prefix: str = "haptic/rig-1"
    listen: tuple[str, ...] = ()
    connect: tuple[str, ...] = ()
    multicast_scouting: bool = False
    express: bool = True
    congestion_control: str = "drop"
    tx_queue_size_real_time: int = 16
    receive_queue_capacity: int = 1024
    lease_s: float = 1.0
    max_message_age_s: float = 0.03
    stale_after_s: float = 0.05
    resync_messages: int = 20
    max_samples_per_poll: int = 64
    session_key: bytes | None = field(default=None, repr=False)
    """The pre-shared key of an authenticated link (32 bytes), or None."""
    seed: int = 0
    injection: InjectionConfig = field(default_factory=InjectionConfig)
    zenoh_config_file: str | None = None
    zenoh_overrides: tuple[tuple[str, str], ...] = ()

    def __post_init__(self) -> None:
        if self.side not in SIDES:
            raise ConfigError("side", f"must be one of {', '.join(SIDES)} (got {self.side!r})")
        if self.mode not in MODES:
            raise ConfigError("link.transport.mode", f"must be one of {', '.join(MODES)}")
        if self.mode == "client" and not self.connect:
            raise ConfigError(
                f"link.{self.side}.endpoints.connect", "client mode needs the router's endpoint"
            )
        problem = _key_prefix_check(self.key_prefix)
        if problem:
            raise ConfigError("link.transport.key_prefix", problem)
        for name in ("listen", "connect"):
            for endpoint in getattr(self, name):
                problem = endpoint_problem(endpoint)
                if problem:
                    raise ConfigError(f"link.{self.side}.endpoints.{name}", problem)

    @property
    def peer_side(self) -> str:
        return "slave" if self.side == "master" else "master"

    def key(self, what: str) -> str:
        """``<prefix>/<what>``."""
        return f"{self.key_prefix}/{what}"

    @property
    def publish_key(self) -> str:
        """This side's messages: ``<prefix>/handle`` (master) or ``<prefix>/tool`` (slave)."""
        return self.key("handle" if self.side == "master" else "tool")

    @property
    def subscribe_key(self) -> str:
        return self.key("tool" if self.side == "master" else "handle")

    def liveliness_key(self, side: str) -> str:
        """``<prefix>/alive/<side>``."""
        return self.key(f"alive/{side}")

    def zenoh_settings(self) -> list[tuple[str, str]]:
        """The ``(key, json5 value)`` pairs this config inserts into the zenoh config, in order
        (the overrides last)."""
        settings = [
            ("mode", json.dumps(self.mode)),
            ("scouting/multicast/enabled", json.dumps(self.multicast_scouting)),
            ("transport/link/tx/queue/size/real_time", str(self.tx_queue_size_real_time)),
            ("transport/link/tx/lease", str(max(1, round(self.lease_s * 1000)))),
        ]
        if self.listen and self.mode != "client":  # a client only connects (to its router)
            settings.append(("listen/endpoints", json.dumps(list(self.listen))))
        if self.connect:
            settings.append(("connect/endpoints", json.dumps(list(self.connect))))
        settings.extend(self.zenoh_overrides)
        return settings


def injection_from_table(table: dict[str, Any]) -> InjectionConfig:
    """An :class:`InjectionConfig` from a validated ``[link.<side>.injection]`` table (its
    ``seed`` goes to :class:`LinkConfig`)."""
    values = {k: v for k, v in table.items() if k not in ("seed", "delay_profile")}
    return InjectionConfig(**values,
                           delay_profile=parse_delay_profile(table.get("delay_profile", "")))


def link_config_from(config: dict[str, Any], side: str, **changes: Any) -> LinkConfig:
    """The :class:`LinkConfig` of ``side`` from a validated configuration (``load_config``);
    ``changes`` replace fields (CLI flags). Raises :class:`ConfigError`."""
    if side not in SIDES:
        raise ConfigError("side", f"must be one of {', '.join(SIDES)} (got {side!r})")
    link = config["link"]
    transport = link["transport"]
    watchdog = link["watchdog"]
    own = link[side]
    values: dict[str, Any] = {
        "side": side,
        "listen": split_endpoints(own["endpoints"]["listen"]),
        "connect": split_endpoints(own["endpoints"]["connect"]),
        "injection": injection_from_table(own["injection"]),
        "seed": own["injection"]["seed"],
        **transport,
        **watchdog,
        **{k: v for k, v in link["security"].items() if k != "session_key_file"},
    }
    key_file = link["security"]["session_key_file"]
    if key_file:
        from haptic.common.auth import load_key_file

        values["session_key"] = load_key_file(key_file)
    values.update(changes)
    return LinkConfig(**values)
