"""Helpers of the link tests over real Zenoh on loopback: a free port, pairing two links."""

from __future__ import annotations

import time

from haptic.common.wire.link import Link

#: How long a test waits for a pairing, s.
WAIT_S = 15.0


def pair(*links: Link) -> None:
    """Poll ``links`` until each sees its peer and is paired (at most :data:`WAIT_S`)."""
    deadline = time.monotonic() + WAIT_S
    while not all(link.peer_alive and link.paired for link in links):
        for link in links:
            link.poll()
        assert time.monotonic() < deadline, "no pairing"
        time.sleep(0.001)
