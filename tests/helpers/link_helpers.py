"""Helpers of the link tests over real Zenoh on loopback: a master/slave pair of link
configurations on a free port, and waiting until two links see (or pair with) each other."""

from __future__ import annotations

import time
import uuid

from haptic.common.wire.injection import InjectionConfig
from haptic.common.wire.link import Link
from haptic.common.wire.link_config import LinkConfig
from haptic.common.wire.ports import free_port

#: How long a test waits for a pairing, s.
WAIT_S = 15.0


def configs(slave_injection: InjectionConfig | None = None,
            **common: object) -> tuple[LinkConfig, LinkConfig]:
    """A master/slave pair on a fresh port and key prefix. Unless told otherwise the pair
    blocks instead of dropping on congestion and never drops as stale, so exact counts hold
    on a loaded machine (the defaults' drop behaviour is the benchmark's business)."""
    common.setdefault("congestion_control", "block")
    common.setdefault("stale_after_s", 10.0)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    prefix = f"test/{uuid.uuid4().hex[:10]}"
    master = LinkConfig(side="master", key_prefix=prefix, listen=(endpoint,), **common)
    slave = LinkConfig(
        side="slave", key_prefix=prefix, connect=(endpoint,),
        injection=slave_injection or InjectionConfig(), **common,
    )
    return master, slave


def wait_for_peers(*links: Link) -> None:
    """Poll ``links`` until each sees its peer alive (at most :data:`WAIT_S`)."""
    deadline = time.monotonic() + WAIT_S
    while not all(link.peer_alive for link in links):
        for link in links:
            link.poll()
        assert time.monotonic() < deadline, "the peers did not see each other"
        time.sleep(0.001)


def pair(*links: Link) -> None:
    """Poll ``links`` until each sees its peer and is paired (at most :data:`WAIT_S`)."""
    deadline = time.monotonic() + WAIT_S
    while not all(link.peer_alive and link.paired for link in links):
        for link in links:
            link.poll()
        assert time.monotonic() < deadline, "no pairing"
        time.sleep(0.001)
