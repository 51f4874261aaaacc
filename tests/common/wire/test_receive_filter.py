"""The receive path's flood filter and epoch pinning at the value: which first bytes pass
(fixarrays of 6-15 items, array16 headers of 16-31), the 1024-byte limit, what each
rejection counts, and what pinning an epoch does to the sequence and the loss figures."""

from __future__ import annotations

import numpy as np
import pytest

from haptic.common.wire.injection import InjectionConfig
from haptic.common.wire.messages import (
    KIND_HANDLE,
    KIND_TOOL,
    SCHEMA_VERSION,
    DropReason,
    Flags,
    HandleState,
    ToolState,
    encode,
)
from haptic.common.wire.receive import ReceivePath

MS = 1_000_000
T0 = 1_700_000_000_000_000_000


def path(kind: int = KIND_HANDLE) -> ReceivePath:
    return ReceivePath(kind, InjectionConfig(), np.random.default_rng(0), 0.05)


def handle(seq: int, epoch: int = 1) -> bytes:
    return encode(HandleState(epoch, seq, T0 + seq * MS, Flags(0), (1.0, -1.0), (0.01, 0.02)))


def test_every_real_message_passes_the_filter() -> None:
    tool = encode(ToolState(1, 2, T0, Flags(0), (0.0, 0.0), (0.0, 0.0), (0.0, 0.0), 0.0, 0.0))
    assert tool[:3] == b"\xdc\x00\x10"  # 16 items: an array16 header
    assert handle(1)[0] == 0x9D  # 13 items: a fixarray
    p = path()
    assert not p.rejects_at_once(tool) and not p.rejects_at_once(handle(1))
    assert p.stats().received == 0  # passing counts nothing: accept() counts


@pytest.mark.parametrize("first", [0x96, 0x97, 0x9E, 0x9F])
def test_fixarrays_of_6_to_15_items_pass(first) -> None:
    assert not path().rejects_at_once(bytes([first]) + b"\x00" * 20)


@pytest.mark.parametrize("payload", [
    b"", bytes([0x95]) + bytes(20), bytes([0xA0]) + bytes(20), bytes([0xDD, 0, 0, 0, 16]),
    b"\xdc\x00\x0f" + bytes(20), b"\xdc\x00\x20" + bytes(20), b"\xdc\x01\x10" + bytes(20),
    b"\xdc\x00\x10", bytes([0xDB]) + bytes(20), bytes([0x00, 0x9C]) + bytes(20),
])
def test_anything_else_is_rejected_and_counted_once_as_malformed(payload) -> None:
    p = path()
    assert p.rejects_at_once(payload)
    stats = p.stats()
    assert stats.received == 1 and stats.dropped[DropReason.MALFORMED.value] == 1
    assert sum(stats.dropped.values()) == 1


@pytest.mark.parametrize(("third", "passes"), [(16, True), (31, True), (15, False), (32, False)])
def test_array16_item_counts_from_16_to_31(third, passes) -> None:
    assert path().rejects_at_once(b"\xdc\x00" + bytes([third, 0])) is not passes


def test_the_size_limit_is_1024_bytes_inclusive() -> None:
    p = path()
    assert not p.rejects_at_once(b"\x9c" + bytes(1023))
    assert p.rejects_at_once(b"\x9c" + bytes(1024))


def test_drop_counts_one_received_and_its_reason() -> None:
    p = path()
    p.drop(DropReason.UNAUTHENTICATED)
    stats = p.stats()
    assert stats.received == 1 and stats.dropped[DropReason.UNAUTHENTICATED.value] == 1
    assert sum(stats.dropped.values()) == 1


def test_pinning_the_current_epoch_keeps_the_sequence() -> None:
    p = path()
    for seq in range(3):
        p.accept(handle(seq), T0 + seq * MS)
        assert p.release(T0 + seq * MS) is not None
    p.pin_epoch(1)
    p.pin_epoch(1)
    p.accept(handle(3), T0 + 3 * MS)
    assert p.release(T0 + 3 * MS) is not None
    stats = p.stats()
    assert stats.peer_restarts == 0 and stats.expected == 4 and stats.delivered == 4


def test_pinning_a_new_epoch_is_one_restart_and_closes_the_old_runs_count() -> None:
    p = path()
    for seq in (5, 6, 7):  # first 5, highest 7: three expected
        p.accept(handle(seq), T0 + seq * MS)
        p.release(T0 + seq * MS)
    p.pin_epoch(2)
    stats = p.stats()
    assert stats.peer_restarts == 1 and stats.expected == 3
    # from now on only epoch 2: an epoch-1 message (even newer) is unpaired
    p.accept(handle(8, epoch=1), T0 + 8 * MS)
    assert p.release(T0 + 8 * MS) is None
    assert p.stats().dropped[DropReason.UNPAIRED.value] == 1
    p.accept(handle(0, epoch=2), T0 + 9 * MS)
    assert p.release(T0 + 9 * MS) is not None
    p.pin_epoch(3)
    assert p.stats().peer_restarts == 2


def test_pinning_before_any_message_is_no_restart() -> None:
    p = path()
    p.pin_epoch(4)
    assert p.stats().peer_restarts == 0
    p.accept(handle(0, epoch=4), T0)
    assert p.release(T0) is not None


def test_the_latest_unknown_version_is_remembered_and_others_are_not() -> None:
    import msgpack

    p = path()
    p.accept(msgpack.packb([99, KIND_HANDLE, 1, 1, T0, 0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]), T0)
    assert p.last_unknown_version == 99
    # the right version, the wrong kind: not a version
    p.accept(msgpack.packb([SCHEMA_VERSION, KIND_TOOL, 1, 1, T0, 0]), T0)
    assert p.last_unknown_version == 99
    assert path().last_unknown_version is None
