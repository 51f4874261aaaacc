"""Protected mode: a Zenoh session other hosts can reach is authenticated, or says it is not.

A session that listens on or connects to a non-loopback address with neither a session key
(common/wire/auth.py, common/wire/transport_auth.py) nor mutual TLS lets any host that reaches
it drive the handle and the tool. As Redis's protected mode does, the programs then refuse to
start, with one line naming the ways out, unless the user says ``--insecure``
(``[link.security] insecure = true``); a session run that way says it is unauthenticated in
its status line and summary. Loopback without a key stays allowed (one trusted host).

What counts as reachable from other hosts (:func:`exposure`) is read from the *effective*
Zenoh configuration (the ``--zenoh-config`` file, the ``[link]`` settings and the
``--zenoh-set`` overrides together), so no layer slips past:

- every listen and connect endpoint whose host is not loopback. Loopback is 127.0.0.0/8, ::1
  and the name ``localhost``; a wildcard (``0.0.0.0``, ``[::]``) and any other host name are
  not. The protocol does not matter (tcp, udp, tls, quic, ws; a serial line leaves the host
  too); only Unix sockets and pipes (``unixsock-stream``, ``unixpipe``) stay on it.
- Zenoh's own default listeners where the configuration sets none (a peer listens on
  ``tcp/[::]:0``, every interface; common/wire/link_config.py sets none for a side without
  listen endpoints unless a Zenoh file is given).
- multicast scouting, where the mode connects to what it finds (peer and client by Zenoh's
  defaults): the session announces itself to the LAN and opens transports to whoever answers.
  A router (its default autoconnect is empty) only answers scouts with its listen locators,
  which are judged one by one. Gossip scouting is not counted: it passes on the locators of
  peers this session is already connected to, each judged where it is configured.

Mutual TLS (:func:`mutual_tls_problem`): every reachable endpoint is ``tls`` or ``quic``;
``transport/link/tls`` has ``enable_mtls`` and a root CA (the other end's certificate is
verified against it) and this side's own certificate and key for the directions it uses; with
multicast scouting, ``transport/link/protocols`` admits only tls and quic (else a stranger's
advertised tcp locator would be connected to). A tls endpoint that does not verify the client's
certificate is encrypted, not authenticated: it does not count.
"""

from __future__ import annotations

import ipaddress
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import zenoh

from haptic.common.config import ConfigError

#: Protocols whose endpoints never leave the host.
LOCAL_PROTOCOLS = frozenset({"unixsock-stream", "unixpipe"})
#: Protocols that run over TLS (Zenoh's ``transport/link/tls`` settings apply).
TLS_PROTOCOLS = frozenset({"tls", "quic"})
#: Host names taken as loopback (any other name may resolve anywhere).
LOOPBACK_NAMES = frozenset({"localhost"})
#: Zenoh's defaults where a configuration leaves the key unset (eclipse-zenoh 1.x).
ZENOH_DEFAULT_LISTEN = {"router": ["tcp/[::]:7447"], "peer": ["tcp/[::]:0"], "client": []}
ZENOH_DEFAULT_AUTOCONNECT = {"router": [], "peer": ["router", "peer"], "client": ["router"]}
MULTICAST = "multicast scouting"

#: The ways out of a refusal for haptic-master and haptic-slave.
PROGRAM_WAYS_OUT = (
    "give both sides --session-key FILE ([link.security] session_key_file), or mutual TLS "
    "(--zenoh-config FILE with transport/link/tls enable_mtls, deploy/zenoh/), or say "
    "--insecure ([link.security] insecure = true) to run unauthenticated")


def endpoint_host(endpoint: str) -> str | None:
    """The host of a Zenoh locator ``proto/host:port[?metadata][#config]`` (IPv6 without its
    brackets and zone), or ``None`` for a protocol that stays on the host."""
    proto, _, address = endpoint.partition("/")
    if proto in LOCAL_PROTOCOLS:
        return None
    address = address.split("#", 1)[0].split("?", 1)[0].strip()
    if address.startswith("["):
        host = address[1:].partition("]")[0]
    elif address.count(":") == 1:
        host = address.partition(":")[0]
    else:
        host = address  # a bare IPv6 address, a name, or a serial device
    return host.partition("%")[0]


def is_loopback_host(host: str) -> bool:
    """127.0.0.0/8, ::1 (also IPv4-mapped) and ``localhost``; not a wildcard, not any other
    name (it may resolve to any address)."""
    if host.lower().rstrip(".") in LOOPBACK_NAMES:
        return True
    try:
        address = ipaddress.ip_address(host)
    except ValueError:
        return False
    mapped = getattr(address, "ipv4_mapped", None)
    return bool(address.is_loopback or (mapped is not None and mapped.is_loopback))


def reaches_other_hosts(endpoint: str) -> bool:
    """Whether ``endpoint`` (a Zenoh locator) listens or connects beyond this host."""
    host = endpoint_host(endpoint)
    return host is not None and not is_loopback_host(host)


@dataclass(frozen=True)
class ZenohSettings:
    """The parts of an effective Zenoh configuration the protected mode judges (plain data;
    ``None`` where the configuration leaves a key to Zenoh's default)."""

    mode: str = "peer"
    listen: Any = None
    connect: Any = None
    multicast: bool | None = None
    autoconnect: Any = None
    tls: Mapping[str, Any] | None = None
    protocols: Sequence[str] | None = None

    @classmethod
    def of(cls, config: zenoh.Config) -> ZenohSettings:
        """Read ``config`` (a built ``zenoh.Config``)."""

        def get(key: str) -> Any:
            return json.loads(config.get_json(key))

        return cls(mode=get("mode") or "peer", listen=get("listen/endpoints"),
                   connect=get("connect/endpoints"),
                   multicast=get("scouting/multicast/enabled"),
                   autoconnect=get("scouting/multicast/autoconnect"),
                   tls=get("transport/link/tls"), protocols=get("transport/link/protocols"))


def _for_mode(value: Any, mode: str, default: Mapping[str, list[str]]) -> list[str]:
    """A Zenoh mode-dependent value (a list, a ``"a|b"`` string, or a table by mode) for
    ``mode``; ``None`` is Zenoh's ``default``."""
    if value is None:
        value = default
    if isinstance(value, Mapping):
        value = value.get(mode) or []
    if isinstance(value, str):
        value = [part for part in value.split("|") if part]
    return [str(item) for item in value]


@dataclass(frozen=True)
class Exposure:
    """What of a session other hosts can reach: the listen and connect endpoints beyond
    loopback, and whether multicast scouting connects to what it finds on the LAN."""

    listen: tuple[str, ...] = ()
    connect: tuple[str, ...] = ()
    multicast_scouting: bool = False

    @property
    def reachable(self) -> bool:
        return bool(self.listen or self.connect or self.multicast_scouting)

    @property
    def items(self) -> list[str]:
        """``listen E``, ``connect E`` and ``multicast scouting``, in that order."""
        return ([f"listen {e}" for e in self.listen] + [f"connect {e}" for e in self.connect]
                + ([MULTICAST] if self.multicast_scouting else []))


def exposure(settings: ZenohSettings) -> Exposure:
    """What of the session ``settings`` describe other hosts can reach (module docstring)."""
    mode = settings.mode
    listen = [] if mode == "client" else _for_mode(settings.listen, mode, ZENOH_DEFAULT_LISTEN)
    connect = _for_mode(settings.connect, mode, {})
    multicast = settings.multicast is not False and bool(
        _for_mode(settings.autoconnect, mode, ZENOH_DEFAULT_AUTOCONNECT))
    return Exposure(tuple(e for e in listen if reaches_other_hosts(e)),
                    tuple(e for e in connect if reaches_other_hosts(e)), multicast)


def _set(tls: Mapping[str, Any], key: str) -> bool:
    return bool(tls.get(key) or tls.get(f"{key}_base64"))


def mutual_tls_problem(settings: ZenohSettings, reach: Exposure) -> str | None:
    """Why the session's reachable part is not mutual TLS, or ``None`` when it is (module
    docstring)."""
    plain = [e for e in reach.listen + reach.connect if e.partition("/")[0] not in TLS_PROTOCOLS]
    if plain:
        return f"{plain[0]} is not tls or quic"
    tls = settings.tls or {}
    if tls.get("enable_mtls") is not True:
        return "transport/link/tls enable_mtls is not true"
    if not _set(tls, "root_ca_certificate"):
        return "transport/link/tls has no root_ca_certificate"
    connects = bool(reach.connect) or reach.multicast_scouting
    for end, used in (("listen", bool(reach.listen)), ("connect", connects)):
        if used and not (_set(tls, f"{end}_certificate") and _set(tls, f"{end}_private_key")):
            return f"transport/link/tls has no {end}_certificate and {end}_private_key"
    if reach.multicast_scouting and not (
            settings.protocols and set(settings.protocols) <= TLS_PROTOCOLS):
        return "multicast scouting with transport/link/protocols other than tls and quic"
    return None


@dataclass(frozen=True)
class Protection:
    """The verdict on one session: what reaches other hosts, and what authenticates it."""

    exposure: Exposure
    session_key: bool
    mutual_tls: bool
    insecure: bool

    @property
    def unauthenticated(self) -> bool:
        """Neither a session key nor mutual TLS: nothing says who sent a message."""
        return not (self.session_key or self.mutual_tls)

    @property
    def allowed(self) -> bool:
        """Loopback only, authenticated, or unauthenticated because the user said so."""
        return not (self.exposure.reachable and self.unauthenticated and not self.insecure)

    @property
    def label(self) -> str:
        """``session key``, ``mutual TLS``, both, ``loopback`` or ``none (--insecure)``."""
        if not self.unauthenticated:
            return " + ".join(name for name, on in (("session key", self.session_key),
                                                    ("mutual TLS", self.mutual_tls)) if on)
        return "none (--insecure)" if self.insecure else "loopback"

    @property
    def marker(self) -> str:
        """What the status line and the summary show: ``UNAUTHENTICATED (--insecure)`` for
        a session the user let run without a key or mutual TLS, else empty."""
        return "UNAUTHENTICATED (--insecure)" if self.insecure and self.unauthenticated else ""

    def summary(self) -> dict[str, object]:
        """The run summary's keys: ``link_protection`` (:attr:`label`),
        ``link_unauthenticated`` and ``link_reachable`` (what other hosts can reach)."""
        return {"link_protection": self.label, "link_unauthenticated": self.unauthenticated,
                "link_reachable": self.exposure.items}


def decide(settings: ZenohSettings, session_key: bool, insecure: bool) -> Protection:
    """The verdict on a session of ``settings`` with or without a session key; never raises
    (:attr:`Protection.allowed` says whether it may start)."""
    reach = exposure(settings)
    mutual = reach.reachable and mutual_tls_problem(settings, reach) is None
    return Protection(reach, session_key, mutual, insecure)


def require_protection(config: zenoh.Config, session_key: bool, insecure: bool,
                       ways_out: str = PROGRAM_WAYS_OUT) -> Protection:
    """The verdict on a session of ``config`` (a built ``zenoh.Config``); raises
    :class:`ConfigError` (key ``link.security``, one line ending in ``ways_out``) when it
    reaches other hosts unauthenticated without ``insecure``. Call it before the session
    opens: nothing is sent."""
    settings = ZenohSettings.of(config)
    verdict = decide(settings, session_key, insecure)
    if verdict.allowed:
        return verdict
    reach = verdict.exposure
    problem = mutual_tls_problem(settings, reach)
    tls_note = ""
    if any(e.partition("/")[0] in TLS_PROTOCOLS for e in reach.listen + reach.connect):
        tls_note = f" (not mutual TLS: {problem})"
    raise ConfigError("link.security", (
        f"protected mode: the session reaches other hosts ({', '.join(reach.items)}) with "
        f"neither a session key nor mutual TLS{tls_note}, so anyone who reaches it could "
        f"drive the handle and the tool: {ways_out}"))
