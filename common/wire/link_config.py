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

from haptic.common.config import ConfigError
from haptic.common.config.link_schema import (
    MODES,
    SIDES,
    endpoint_problem,
    key_prefix_problem,
    split_endpoints,
)
from haptic.common.model.delay_profile import parse_delay_profile
from haptic.common.wire.injection import InjectionConfig
from haptic.common.wire.transport_auth import transport_key


@dataclass(frozen=True)
class LinkConfig:
    """Everything :class:`haptic.common.wire.link.Link` needs for one side.

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
    transport_auth: bool = True
    """With a session key in peer mode: Zenoh admits only transports that authenticate with
    credentials derived from it (common/wire/transport_auth.py)."""
    insecure: bool = False
    """Protected mode off: a session that reaches other hosts may open with neither a session
    key nor mutual TLS (common/wire/protected_mode.py); it then says it is unauthenticated."""
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
        problem = key_prefix_problem(self.key_prefix)
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

    @property
    def transport_key(self) -> bytes | None:
        """The key the Zenoh transports authenticate with, or None (no session key,
        ``transport_auth`` off, or client mode)."""
        return transport_key(self.session_key, self.transport_auth, self.mode)

    def zenoh_settings(self) -> list[tuple[str, str]]:
        """The ``(key, json5 value)`` pairs this config inserts into the zenoh config, in order
        (the overrides last)."""
        settings = [
            ("mode", json.dumps(self.mode)),
            ("scouting/multicast/enabled", json.dumps(self.multicast_scouting)),
            ("transport/link/tx/queue/size/real_time", str(self.tx_queue_size_real_time)),
            ("transport/link/tx/lease", str(max(1, round(self.lease_s * 1000)))),
        ]
        if self.mode != "client" and (self.listen or not self.zenoh_config_file):
            # A client only connects (to its router). A peer without listen endpoints listens
            # on none: Zenoh's default is tcp/[::]:0, every interface (with a Zenoh file, the
            # file's listen, or that default, stays: common/wire/protected_mode.py judges it).
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
        from haptic.common.wire.auth import load_key_file

        values["session_key"] = load_key_file(key_file)
    values.update(changes)
    return LinkConfig(**values)
