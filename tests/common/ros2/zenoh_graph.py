"""Test helpers: a Zenoh router on a free loopback port (what rmw_zenohd is to ROS 2) and a
client session that records every sample and liveliness token of one domain, as a ROS 2
subscriber over rmw_zenoh would see them."""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import zenoh

from haptic.common.wire.ports import free_port

__all__ = ["free_port", "ros2_listener", "zenoh_router"]


def _config(mode: str, endpoint: str) -> zenoh.Config:
    config = zenoh.Config()
    config.insert_json5("mode", json.dumps(mode))
    config.insert_json5("listen/endpoints" if mode == "router" else "connect/endpoints",
                        json.dumps([endpoint]))
    config.insert_json5("scouting/multicast/enabled", "false")
    return config


@contextmanager
def zenoh_router(endpoint: str) -> Iterator[Any]:
    """A Zenoh session in router mode listening on ``endpoint``; closed on exit."""
    session = zenoh.open(_config("router", endpoint))
    try:
        yield session
    finally:
        session.close()


@dataclass
class Graph:
    """What a client session saw: samples by data key (payload, attachment) and the
    liveliness tokens put and deleted, in order."""

    samples: dict[str, list[tuple[bytes, bytes | None]]] = field(default_factory=dict)
    tokens: list[tuple[str, str]] = field(default_factory=list)
    lock: threading.RLock = field(default_factory=threading.RLock)

    def on_sample(self, sample: Any) -> None:
        attachment = sample.attachment.to_bytes() if sample.attachment is not None else None
        with self.lock:
            self.samples.setdefault(str(sample.key_expr), []).append(
                (sample.payload.to_bytes(), attachment))

    def on_token(self, sample: Any) -> None:
        with self.lock:
            self.tokens.append((str(sample.key_expr), str(sample.kind)))

    def wait(self, done: Callable[[Graph], bool], timeout_s: float) -> bool:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            with self.lock:
                if done(self):
                    return True
            time.sleep(0.05)
        return False

    def alive_tokens(self) -> set[str]:
        with self.lock:
            alive: set[str] = set()
            for key, kind in self.tokens:
                (alive.add if kind.endswith("PUT") else alive.discard)(key)
            return alive


@contextmanager
def ros2_listener(endpoint: str, domain_id: int = 0) -> Iterator[Graph]:
    """A client session subscribed to every data key and liveliness token of
    ``domain_id``; undeclared and closed on exit."""
    graph = Graph()
    session = zenoh.open(_config("client", endpoint))
    try:
        subscriber = session.declare_subscriber(f"{domain_id}/**", graph.on_sample)
        tokens = session.liveliness().declare_subscriber(f"@ros2_lv/{domain_id}/**",
                                                         graph.on_token, history=True)
        try:
            yield graph
        finally:
            subscriber.undeclare()
            tokens.undeclare()
    finally:
        session.close()
