"""Authenticated sessions on the link: a pre-shared key, a per-session key, a tag per message.

Without a key (``[link.security] session_key_file = ""``) the link trusts every message on
its keys (one trusted host; README, Security). With one, only the paired peer's messages move
anything:

**Pairing.** Each side draws a random 16-byte nonce and its epoch once per run, and publishes a
*hello* on ``<prefix>/pair/<side>`` every :data:`HELLO_PERIOD_S` (and at once after pairing
with a new peer)::

    msgpack [SCHEMA_VERSION, KIND_HELLO, side, epoch, nonce, time_ns, authenticated
             (, control)] + tag

the tag being HMAC-SHA256(pre-shared key, hello body)[:16] (no tag without a key), the 8th
field included. ``control`` is present only on a side that runs a lane law (its
``[control] mode``: 1 to :data:`CONTROL_MAX_CHARS` characters of ``[a-z0-9-]``, e.g.
``"wave"``); a hello of 7 fields comes from a side that exchanges the programs' own messages
(``[control] mode`` "paper" or "tdpa", which their flags tell apart). The link refuses to
pair with a peer whose control differs from its own (common/wire/link.py). A hello is
accepted only with a valid tag, from the peer's side, at most :data:`HELLO_MAX_AGE_S` old and
newer than the hello the current pairing came from; a replayed old hello changes nothing. A
hello with a new (epoch, nonce) is an explicit re-pairing (the peer restarted): both sides
derive the session key::

    K = HMAC-SHA256(psk, "haptic-teleop/2/session" | master nonce | slave nonce |
                    master epoch (4 bytes) | slave epoch (4 bytes))

so every run has its own key, and nothing recorded in an earlier run verifies in this one.

**Messages.** Every data message carries HMAC-SHA256(K, message)[:16] after its msgpack body:
the tag covers the version, kind, epoch, sequence number, send time, flags and payload. The
receiver drops a message that does not verify (``unauthenticated``), one that comes before
any pairing or from another epoch than the paired one (``unpaired``; a new epoch comes only
from an authenticated hello, never from a message's newer send time), and, as before, one
whose sequence number is not above the highest seen (a replay: ``out_of_order``).

The pre-shared key file holds 64 hex digits (32 bytes) and must not be readable by group or
others (``chmod 600``); :func:`write_key_file` makes one (``haptic-session`` does, per run).
"""

from __future__ import annotations

import hashlib
import hmac
import os
import re
import secrets
import stat
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import msgpack

from haptic.common.config import ConfigError
from haptic.common.wire.messages import SCHEMA_VERSION

TAG_BYTES = 16
KEY_BYTES = 32
NONCE_BYTES = 16
KIND_HELLO = 3
HELLO_PERIOD_S = 0.1
HELLO_MAX_AGE_S = 5.0
_SIDE_CODE = {"master": 1, "slave": 2}
_SIDE_NAME = {code: side for side, code in _SIDE_CODE.items()}
_SESSION_LABEL = b"haptic-teleop/2/session"
#: The longest control name a hello may carry, characters.
CONTROL_MAX_CHARS = 32
_CONTROL_NAME = re.compile(rf"[a-z0-9-]{{1,{CONTROL_MAX_CHARS}}}")


def is_control_name(value: object) -> bool:
    """Whether ``value`` may be a hello's control: a str of 1 to :data:`CONTROL_MAX_CHARS`
    characters, each of ``a-z``, ``0-9`` or ``-`` (ASCII only)."""
    return type(value) is str and _CONTROL_NAME.fullmatch(value) is not None


def load_key_file(path: str | Path, key: str = "link.security.session_key_file") -> bytes:
    """The 32-byte pre-shared key in ``path`` (64 hex digits). Raises :class:`ConfigError`
    naming ``key`` for a missing, unreadable, malformed or group/world-readable file."""
    file = Path(path)
    try:
        mode = file.stat().st_mode
        text = file.read_bytes().decode("ascii").strip()
    except OSError as error:
        raise ConfigError(key, f"cannot read {path}: {error.strerror}") from None
    except UnicodeDecodeError:
        raise ConfigError(key, f"{path} is not 64 hex digits") from None
    if mode & (stat.S_IRWXG | stat.S_IRWXO):
        raise ConfigError(key, f"{path} is readable by others (mode {stat.S_IMODE(mode):o}); "
                          "chmod 600 it")
    try:
        secret = bytes.fromhex(text)
    except ValueError:
        secret = b""
    if len(secret) != KEY_BYTES:
        raise ConfigError(key, f"{path} is not 64 hex digits (a 32-byte key)")
    return secret


def write_key_file(path: str | Path) -> Path:
    """Write a fresh random pre-shared key to ``path`` (mode 600); returns the path."""
    file = Path(path)
    descriptor = os.open(file, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(descriptor, "w") as stream:
        stream.write(secrets.token_hex(KEY_BYTES) + "\n")
    os.chmod(file, 0o600)
    return file


def _mac(key: bytes, data: bytes) -> bytes:
    return hmac.new(key, data, hashlib.sha256).digest()[:TAG_BYTES]


@dataclass(frozen=True)
class Hello:
    """A decoded hello: the sender's side, epoch, nonce, CLOCK_REALTIME time (ns), whether
    it authenticates and the lane law it runs (``control``; None: the programs' own messages,
    "paper" or "tdpa"); ``version`` is its wire schema version."""

    version: int
    side: str
    epoch: int
    nonce: bytes
    time_ns: int
    authenticated: bool
    control: str | None = None


class HelloError(ValueError):
    """A hello that is not one (malformed) or that does not verify."""


def encode_hello(side: str, epoch: int, nonce: bytes, time_ns: int,
                 psk: bytes | None, control: str | None = None) -> bytes:
    """A hello of ``side`` (tagged with the pre-shared key ``psk`` when given), with the lane
    law ``control`` as its 8th field when given. Raises ValueError for a ``control`` that
    :func:`is_control_name` refuses (the peer would refuse the hello)."""
    fields = [SCHEMA_VERSION, KIND_HELLO, _SIDE_CODE[side], int(epoch), nonce, int(time_ns),
              psk is not None]
    if control is not None:
        if not is_control_name(control):
            raise ValueError(f"a hello's control is 1 to {CONTROL_MAX_CHARS} characters of "
                             f"[a-z0-9-], not {control!r}")
        fields.append(control)
    body = msgpack.packb(fields, use_bin_type=True)
    return body + _mac(psk, body) if psk is not None else body


def decode_hello(payload: bytes, psk: bytes | None) -> Hello:
    """Parse a hello of 7 fields, or 8 with a control (:func:`is_control_name`); with ``psk``
    its tag must verify. Raises :class:`HelloError`. A hello of another schema version
    decodes as far as its version (so the caller can say so)."""
    if len(payload) > 256:
        raise HelloError("too long")
    try:
        unpacker = msgpack.Unpacker(raw=False)
        unpacker.feed(payload)
        fields = unpacker.unpack()
        body_length = unpacker.tell()
    except Exception:  # noqa: BLE001 - msgpack raises many types for corrupt input
        raise HelloError("not msgpack") from None
    # every field checked as exactly its type (``type(x) is int``: a bool or a float that
    # equals an int is not one, and a list or map must not reach a dict lookup)
    if (not isinstance(fields, list) or len(fields) < 2 or type(fields[1]) is not int
            or fields[1] != KIND_HELLO):
        raise HelloError("not a hello")
    version = fields[0]
    if version != SCHEMA_VERSION or type(version) is not int:
        return Hello(version if type(version) is int else -1, "", 0, b"", 0, False)
    if len(fields) not in (7, 8):
        raise HelloError("wrong shape")
    _, _, side_code, epoch, nonce, time_ns, authenticated = fields[:7]
    control = fields[7] if len(fields) == 8 else None
    if (type(side_code) is not int or side_code not in _SIDE_NAME
            or type(epoch) is not int or not 0 <= epoch < 2**32
            or type(nonce) is not bytes or len(nonce) != NONCE_BYTES
            or type(time_ns) is not int or not 0 <= time_ns < 2**63
            or type(authenticated) is not bool
            or (len(fields) == 8 and not is_control_name(control))):
        raise HelloError("bad field")
    tag = payload[body_length:]
    if authenticated and psk is not None:
        if len(tag) != TAG_BYTES or not hmac.compare_digest(tag, _mac(psk, payload[:body_length])):
            raise HelloError("tag does not verify")
    elif tag and not authenticated:
        raise HelloError("trailing bytes")
    # without a psk an authenticated hello is returned unverified: the caller can only
    # report the mismatch, never pair on it
    return Hello(version, _SIDE_NAME[side_code], epoch, nonce, time_ns, authenticated, control)


class SessionAuth:
    """One side's pairing state and message tags (not thread-safe: the loop's thread).

    ``psk``: the pre-shared key (32 bytes); ``side``: ``master`` or ``slave``; ``epoch``:
    this run's epoch.
    """

    def __init__(self, psk: bytes, side: str, epoch: int) -> None:
        if len(psk) != KEY_BYTES:
            raise ValueError("the pre-shared key must be 32 bytes")
        self._psk = psk
        self.side = side
        self.peer_side = "slave" if side == "master" else "master"
        self.epoch = epoch
        self.nonce = secrets.token_bytes(NONCE_BYTES)
        self.peer: Hello | None = None
        self._peer_time_ns = 0
        self._mac: Any = None
        self.pairings = 0
        self.rejected_hellos = 0

    @property
    def paired(self) -> bool:
        return self._mac is not None

    @property
    def peer_epoch(self) -> int | None:
        return None if self.peer is None else self.peer.epoch

    def hello(self, now_ns: int, control: str | None = None) -> bytes:
        """This side's hello, stamped ``now_ns`` (CLOCK_REALTIME), announcing the lane law
        ``control`` this side runs (None: the programs' own messages)."""
        return encode_hello(self.side, self.epoch, self.nonce, now_ns, self._psk, control)

    def accept_hello(self, hello: Hello, now_ns: int) -> bool:
        """Take a verified hello (:func:`decode_hello` with the psk); True when it paired this
        side with a new peer run (re-derived the session key). Every hello refused is counted
        in :attr:`rejected_hellos`: from the wrong side, unauthenticated, more than
        :data:`HELLO_MAX_AGE_S` from ``now_ns`` either way (a replay, or clocks that differ
        that much), or not newer than the last one taken (a replay)."""
        if (hello.side != self.peer_side or not hello.authenticated
                or abs(now_ns - hello.time_ns) > HELLO_MAX_AGE_S * 1e9
                or hello.time_ns <= self._peer_time_ns):
            self.rejected_hellos += 1
            return False
        self._peer_time_ns = hello.time_ns
        current = self.peer
        if current is not None and (current.epoch, current.nonce) == (hello.epoch, hello.nonce):
            return False  # the same peer run, a later hello: nothing changes
        self.peer = hello
        master, slave = (self, hello) if self.side == "master" else (hello, self)
        session_key = hmac.new(
            self._psk, _SESSION_LABEL + master.nonce + slave.nonce
            + master.epoch.to_bytes(4, "big") + slave.epoch.to_bytes(4, "big"),
            hashlib.sha256).digest()
        self._mac = hmac.new(session_key, digestmod=hashlib.sha256)
        self.pairings += 1
        return True

    def tag(self, body: bytes) -> bytes:
        """The 16-byte tag of a data message under the session key (paired only)."""
        mac = self._mac.copy()
        mac.update(body)
        return mac.digest()[:TAG_BYTES]

    def verify(self, payload: bytes) -> bytes | None:
        """The body of a tagged data message when its tag verifies, else None."""
        if self._mac is None or len(payload) <= TAG_BYTES:
            return None
        body = payload[:-TAG_BYTES]
        mac = self._mac.copy()
        mac.update(body)
        if hmac.compare_digest(mac.digest()[:TAG_BYTES], payload[-TAG_BYTES:]):
            return body
        return None
