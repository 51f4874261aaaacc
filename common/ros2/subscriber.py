"""Receiving one ROS 2 topic from rmw_zenoh publishers: the building block for a robot on
the other end of the link (its contact force on a WrenchStamped topic, its pose).

A :class:`Ros2Subscription` declares the Zenoh subscriber on the topic's data key and the
subscriber's liveliness token (``MS``, so ``ros2 topic info`` counts it), and keeps only the
newest sample: Zenoh's callback stores the payload and its attachment (a reference swap);
:meth:`Ros2Subscription.newest` deserializes it on the caller's thread. As rmw_zenoh does,
a sample without a well-formed attachment is dropped (counted in ``malformed``); a gap in a
publisher's sequence numbers is counted in ``lost``. :meth:`Ros2Subscription.age_s` is what
a watchdog reads: seconds since the newest sample arrived (infinite before the first).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

from haptic.common.ros2 import messages
from haptic.common.ros2.rmw_format import NodeName, Qos, data_keyexpr, parse_attachment

#: Reliable, volatile, keep last 10.
DEFAULT_QOS = Qos(depth=10)


@dataclass(frozen=True)
class Received:
    """One sample: the message, its publisher's sequence number and source time (ns), its
    GID, and when it arrived (``time.monotonic()``, s)."""

    message: Any
    sequence: int
    source_time_ns: int
    gid: bytes
    arrived_s: float


class Ros2Subscription:
    """The newest sample of ``topic`` (full ROS name) of ``type_name`` on ``session``, for
    node ``node`` as its entity ``entity_id``; see the module docstring."""

    def __init__(self, session: Any, node: NodeName, entity_id: int, topic: str,
                 type_name: str, qos: Qos = DEFAULT_QOS) -> None:
        type_hash = messages.type_hash(type_name)
        self.type_name = type_name
        self.key = data_keyexpr(node.domain_id, topic, type_name, type_hash)
        self.token_key = node.endpoint_token(entity_id, "MS", topic, type_name, type_hash, qos)
        self._newest: tuple[bytes, int, int, bytes, float] | None = None
        self._last_sequence: dict[bytes, int] = {}
        self.received = 0
        self.malformed = 0
        self.lost = 0
        self._subscriber = session.declare_subscriber(self.key, self._on_sample)
        self._token = session.liveliness().declare_token(self.token_key)

    def _on_sample(self, sample: Any) -> None:
        """Zenoh's thread: check the attachment, count gaps, keep the newest payload."""
        try:
            attached = sample.attachment
            sequence, stamp_ns, gid = parse_attachment(
                attached.to_bytes() if attached is not None else b"")
        except ValueError:
            self.malformed += 1
            return
        last = self._last_sequence.get(gid)
        if last is not None and sequence > last + 1:
            self.lost += sequence - last - 1
        self._last_sequence[gid] = sequence
        self.received += 1
        self._newest = (sample.payload.to_bytes(), sequence, stamp_ns, gid, time.monotonic())

    def newest(self) -> Received | None:
        """The newest sample, deserialized (None before the first; a payload that does not
        deserialize counts as malformed and gives None)."""
        newest = self._newest
        if newest is None:
            return None
        payload, sequence, stamp_ns, gid, arrived_s = newest
        try:
            message = messages.deserialize(payload, self.type_name)
        except Exception:  # noqa: BLE001 - a foreign payload: counted, not raised
            self.malformed += 1
            self._newest = None
            return None
        return Received(message, sequence, stamp_ns, gid, arrived_s)

    def age_s(self, now_s: float | None = None) -> float:
        """Seconds since the newest sample arrived (``time.monotonic()`` clock); infinite
        before the first."""
        newest = self._newest
        if newest is None:
            return float("inf")
        return (time.monotonic() if now_s is None else now_s) - newest[4]

    def close(self) -> None:
        """Withdraw the token and undeclare the subscriber."""
        for entity in (self._token, self._subscriber):
            try:
                entity.undeclare()
            except Exception:  # noqa: BLE001 - best effort while stopping
                pass
