"""Zenoh transport authentication from the session key: a stranger cannot join the session.

The message tags of common/wire/auth.py keep a stranger's messages from moving anything, but
the stranger still joins the Zenoh session: it can read every position and force, and flood
the keys (each junk message costs the receiving program's Zenoh threads CPU before the loop
drops it). With a session key and ``[link.security] transport_auth`` (on by default), a
program's Zenoh session in peer mode also requires Zenoh's user-password authentication of
every transport opened to it, with credentials derived from the same pre-shared key::

    user "haptic", password = HMAC-SHA256(psk, "haptic-teleop/2/zenoh-transport"), 64 hex digits

A process without the key cannot open a transport to either program: it cannot publish on
their keys (forge, replay, flood), subscribe to them (read the positions and forces) or see
their liveliness tokens. A peer with another key or none is refused the same way; it then waits
for its peer, and the programs say to check both sides' keys. The message tags stay: in client
mode the link goes through a router (deploy/), which this does not cover (there mTLS and the
access control keep strangers out).

Zenoh reads the accepted credentials from a dictionary file when the session opens
(``transport/auth/usrpwd/dictionary_file``). :func:`open_session` writes it to a private
temporary directory (mode 700, the file 600) and removes it as soon as Zenoh has read it.
"""

from __future__ import annotations

import hashlib
import hmac
import json
import os
import shutil
import tempfile
from pathlib import Path

import zenoh

#: The user name of the programs' transports (any side: the password is what matters).
TRANSPORT_USER = "haptic"
_PASSWORD_LABEL = b"haptic-teleop/2/zenoh-transport"


def transport_password(psk: bytes) -> str:
    """The Zenoh user-password password of the pre-shared key ``psk`` (64 hex digits)."""
    return hmac.new(psk, _PASSWORD_LABEL, hashlib.sha256).hexdigest()


def transport_key(session_key: bytes | None, transport_auth: bool, mode: str) -> bytes | None:
    """The key to authenticate the Zenoh transports with, or ``None`` when they are not: no
    session key, ``transport_auth`` off, or client mode (the router is not ours to configure)."""
    if session_key is None or not transport_auth or mode != "peer":
        return None
    return session_key


def open_session(config: zenoh.Config, psk: bytes | None) -> zenoh.Session:
    """``zenoh.open(config)``; with ``psk``, every transport opened to or by this session must
    authenticate with the credentials derived from it (the dictionary file exists only while
    Zenoh opens the session). Raises ``zenoh.ZError`` as ``zenoh.open`` does."""
    if psk is None:
        return zenoh.open(config)
    password = transport_password(psk)
    folder = Path(tempfile.mkdtemp(prefix="haptic-zenoh-auth-"))  # mode 700
    try:
        dictionary = folder / "credentials.txt"
        descriptor = os.open(dictionary, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(descriptor, "w") as file:
            file.write(f"{TRANSPORT_USER}:{password}\n")
        config.insert_json5("transport/auth/usrpwd", json.dumps(
            {"user": TRANSPORT_USER, "password": password, "dictionary_file": str(dictionary)}))
        return zenoh.open(config)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
