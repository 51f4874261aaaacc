"""rmw_zenoh's wire format: what a Zenoh session must put on the wire for ROS 2 nodes using
``rmw_zenoh_cpp`` to see its topics (ros2/rmw_zenoh, docs/design.md and
rmw_zenoh_cpp/src/detail: attachment_helpers, liveliness_utils, qos, rmw_publisher_data).

The format followed is current rmw_zenoh's: Jazzy from 0.2.4, Kilted and Rolling, on
Zenoh 1.x. Earlier releases (Humble, Jazzy before 0.2.4) put a key/value attachment on
each sample and are not followed.

- Data key: ``<domain>/<topic without outer slashes>/<pkg>::msg::dds_::<Name>_/<hash>``,
  the hash being REP-2011's ``RIHS01_<64 hex>`` of the type description.
- Attachment (a sample without one is dropped by rmw_zenoh): 33 bytes, the Zenoh
  serializer's ``int64, int64, array<uint8, 16>``: the sequence number (from 1), the
  source time (CLOCK_REALTIME, ns), the array's length 16 as one LEB128 byte, the
  publisher's GID (16 bytes, stable per publisher).
- Liveliness tokens (``ros2 node list``, ``ros2 topic list``):
  ``@ros2_lv/<domain>/<zid>/<nid>/<id>/<NN|MP|MS>/<enclave>/<namespace>/<node>`` and, for
  a publisher (``MP``) or subscriber (``MS``), ``/<topic>/<type>/<hash>/<qos>``; every
  ``/`` inside a name becomes ``%`` and an empty name is ``%`` (the root namespace ``/``
  and the default enclave ``/`` are both ``%``). A node's id is its node id (``nid``).
- QoS: ``<reliability>:<durability>:<history>,<depth>:<deadline s>,<ns>:<lifespan s>,<ns>:
  <liveliness>,<lease s>,<ns>`` with rmw's enum values, each field left empty where it is
  rmw_zenoh's default (reliable, volatile, keep last, depth 42, infinite durations,
  automatic liveliness).
- Payload: CDR with its 4-byte encapsulation header (``00 01 00 00``: little-endian CDR).
"""

from __future__ import annotations

import hashlib
import re
import struct
from dataclasses import dataclass

#: The liveliness tokens' admin space.
ADMIN_SPACE = "@ros2_lv"
#: ``struct`` layout of the attachment: int64 sequence number, int64 source time (ns), the
#: GID's length byte (LEB128 of 16), the 16-byte GID; little-endian.
ATTACHMENT_FORMAT = "<qqB16s"
ATTACHMENT_SIZE = struct.calcsize(ATTACHMENT_FORMAT)  # 33
GID_SIZE = 16
#: CDR encapsulation header, little-endian plain CDR.
CDR_LE_HEADER = b"\x00\x01\x00\x00"
#: Domain ids ROS 2 allows (rcl's limit on Linux; REP-2005's port arithmetic).
MAX_DOMAIN_ID = 232

# rmw/types.h enum values
RELIABILITY_RELIABLE = 1
RELIABILITY_BEST_EFFORT = 2
DURABILITY_TRANSIENT_LOCAL = 1
DURABILITY_VOLATILE = 2
HISTORY_KEEP_LAST = 1
HISTORY_KEEP_ALL = 2
#: rmw_zenoh's defaults (rmw_zenoh_cpp/src/detail/qos.cpp); a field equal to it is left empty.
_DEFAULT_RELIABILITY = RELIABILITY_RELIABLE
_DEFAULT_DURABILITY = DURABILITY_VOLATILE
_DEFAULT_HISTORY = HISTORY_KEEP_LAST
_DEFAULT_DEPTH = 42

_TYPE_NAME = re.compile(r"^([A-Za-z][A-Za-z0-9_]*)/msg/([A-Z][A-Za-z0-9]*)$")
_HASH = re.compile(r"^RIHS01_[0-9a-f]{64}$")


@dataclass(frozen=True)
class Qos:
    """The QoS a publisher or subscriber declares (rmw enum values; depth in samples)."""

    reliability: int = RELIABILITY_RELIABLE
    durability: int = DURABILITY_VOLATILE
    history: int = HISTORY_KEEP_LAST
    depth: int = 10


def qos_keyexpr(qos: Qos) -> str:
    """The QoS part of a liveliness token; e.g. best effort, keep last 1: ``2::,1:,:,:,,``."""

    def field(value: int, default: int) -> str:
        return "" if value == default else str(value)

    return (f"{field(qos.reliability, _DEFAULT_RELIABILITY)}:"
            f"{field(qos.durability, _DEFAULT_DURABILITY)}:"
            f"{field(qos.history, _DEFAULT_HISTORY)},{field(qos.depth, _DEFAULT_DEPTH)}:"
            ",:,:,,")  # deadline, lifespan, liveliness: the defaults


def mangle(name: str) -> str:
    """A name as one key chunk: each ``/`` becomes ``%``; an empty name is ``%``."""
    return name.replace("/", "%") or "%"


def dds_type_name(type_name: str) -> str:
    """``geometry_msgs/msg/WrenchStamped`` -> ``geometry_msgs::msg::dds_::WrenchStamped_``."""
    match = _TYPE_NAME.match(type_name)
    if match is None:
        raise ValueError(f"not a ROS 2 message type name: {type_name!r}")
    return f"{match.group(1)}::msg::dds_::{match.group(2)}_"


def full_topic_name(namespace: str, topic: str) -> str:
    """The ROS name of ``topic`` in ``namespace``: absolute topics (``/tf``) stay as they
    are; relative ones go under the namespace (``/haptic`` + ``handle/wrench``)."""
    if topic.startswith("/"):
        return topic
    base = "/" + namespace.strip("/") if namespace.strip("/") else ""
    return f"{base}/{topic}"


def data_keyexpr(domain_id: int, topic: str, type_name: str, type_hash: str) -> str:
    """The data key of a topic (``topic`` is the full ROS name, e.g. ``/haptic/tf``)."""
    check_hash(type_hash)
    return f"{domain_id}/{topic.strip('/')}/{dds_type_name(type_name)}/{type_hash}"


def check_hash(type_hash: str) -> str:
    """``type_hash`` if it is a ``RIHS01_`` hash, else ValueError."""
    if not _HASH.match(type_hash):
        raise ValueError(f"not a RIHS01 type hash: {type_hash!r}")
    return type_hash


@dataclass(frozen=True)
class NodeName:
    """Where a node sits in the graph: domain, Zenoh session id, node id, enclave,
    namespace (``/`` for the root) and name."""

    domain_id: int
    zid: str
    node_id: int
    namespace: str
    name: str
    enclave: str = "/"

    def _prefix(self, entity_id: int, kind: str) -> str:
        return "/".join((ADMIN_SPACE, str(self.domain_id), self.zid, str(self.node_id),
                         str(entity_id), kind, mangle(self.enclave), mangle(self.namespace),
                         mangle(self.name)))

    def node_token(self) -> str:
        """The node's liveliness key (``NN``; its entity id is the node id)."""
        return self._prefix(self.node_id, "NN")

    def endpoint_token(self, entity_id: int, kind: str, topic: str, type_name: str,
                       type_hash: str, qos: Qos) -> str:
        """A publisher's (``MP``) or subscriber's (``MS``) liveliness key; ``topic`` is the
        full ROS name."""
        if kind not in ("MP", "MS"):
            raise ValueError(f"endpoint kind must be MP or MS, not {kind!r}")
        return "/".join((self._prefix(entity_id, kind), mangle(topic),
                         mangle(dds_type_name(type_name)), mangle(check_hash(type_hash)),
                         qos_keyexpr(qos)))


def endpoint_gid(token: str) -> bytes:
    """A 16-byte GID stable for one endpoint: a digest of its liveliness key (rmw_zenoh
    hashes the same key, with XXH3-128; subscribers only compare GIDs for equality)."""
    return hashlib.blake2b(token.encode(), digest_size=GID_SIZE).digest()


def attachment(sequence_number: int, source_time_ns: int, gid: bytes) -> bytes:
    """A sample's 33-byte attachment (see the module docstring)."""
    if len(gid) != GID_SIZE:
        raise ValueError(f"a GID has {GID_SIZE} bytes, not {len(gid)}")
    return struct.pack(ATTACHMENT_FORMAT, sequence_number, source_time_ns, GID_SIZE, gid)


def parse_attachment(data: bytes) -> tuple[int, int, bytes]:
    """``(sequence number, source time ns, GID)`` of an attachment; ValueError if malformed."""
    if len(data) != ATTACHMENT_SIZE:
        raise ValueError(f"an attachment has {ATTACHMENT_SIZE} bytes, not {len(data)}")
    sequence, stamp, length, gid = struct.unpack(ATTACHMENT_FORMAT, data)
    if length != GID_SIZE:
        raise ValueError(f"GID length byte {length}, expected {GID_SIZE}")
    return sequence, stamp, gid
