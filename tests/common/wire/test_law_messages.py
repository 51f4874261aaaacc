"""The lane laws' message schema: round trips, every drop reason, and the receive path with
the law's decoder (pure: no network)."""

from __future__ import annotations

import math

import msgpack
import numpy as np
import pytest

from haptic.common.wire.injection import InjectionConfig
from haptic.common.wire.law_messages import (
    DIRECTIONS,
    LAW_CHANNELS,
    MAX_VALUES,
    LawMessage,
    LawSchema,
    law_kind,
)
from haptic.common.wire.messages import (
    KIND_HANDLE,
    KIND_TOOL,
    SCHEMA_VERSION,
    DecodeError,
    DropReason,
    Flags,
    HandleState,
    decode,
    encode,
)
from haptic.common.wire.receive import ReceivePath

SCHEMAS = [LawSchema(control, direction) for control in LAW_CHANNELS for direction in DIRECTIONS]


def _values(schema: LawSchema) -> tuple[float, ...]:
    return tuple(0.5 * i - 1.25 for i in range(schema.length))


def _message(schema: LawSchema, seq: int = 7, send_time_ns: int = 10**18) -> LawMessage:
    return LawMessage(schema.kind, 123, seq, send_time_ns, Flags.FORCES_ENABLED,
                      _values(schema))


def _raw(schema: LawSchema, body: list, *, version: int = SCHEMA_VERSION,
         kind: int | None = None, seq: object = 1) -> bytes:
    kind = schema.kind if kind is None else kind
    return msgpack.packb([version, kind, 5, seq, 10**18, 0, *body], use_single_float=False)


@pytest.mark.parametrize("schema", SCHEMAS, ids=lambda s: f"{s.control}-{s.direction}")
def test_every_law_message_round_trips(schema: LawSchema) -> None:
    message = _message(schema)
    assert schema.decode(schema.encode(message), schema.kind) == message
    assert len(message.values) == schema.length == LAW_CHANNELS[schema.control][
        DIRECTIONS.index(schema.direction)]


def test_the_declared_lengths_are_the_laws_channels() -> None:
    assert LAW_CHANNELS == {"wave": (6, 6), "four-channel": (6, 6), "mmt": (4, 8),
                            "four-channel-tdpa": (7, 7)}
    # the kinds are fixed by the order: the first laws' stay what they were
    assert [law_kind("wave", "handle"), law_kind("mmt", "tool")] == [16, 21]
    assert max(max(lengths) for lengths in LAW_CHANNELS.values()) <= MAX_VALUES


def test_kinds_name_the_control_and_the_direction() -> None:
    kinds = [schema.kind for schema in SCHEMAS]
    assert len(set(kinds)) == len(kinds)
    assert not set(kinds) & {KIND_HANDLE, KIND_TOOL}
    with pytest.raises(ValueError):
        law_kind("paper", "handle")
    with pytest.raises(ValueError):
        LawSchema("wave", "sideways")


def test_the_send_time_is_stamped_between_the_two_parts() -> None:
    schema = LawSchema("mmt", "tool")
    message = _message(schema, send_time_ns=42)
    before, after = schema.encode_around_send_time(123, 7, int(Flags.FORCES_ENABLED),
                                                   message.values)
    assert schema.decode(before + b"\xcf" + (42).to_bytes(8, "big") + after) == message


def test_the_encoder_refuses_a_wrong_length_or_a_non_finite_value() -> None:
    schema = LawSchema("mmt", "handle")
    with pytest.raises(ValueError, match="carry 4"):
        schema.encode_around_send_time(1, 1, 0, (0.0,) * 5)
    with pytest.raises(ValueError, match="non-finite"):
        schema.encode_around_send_time(1, 1, 0, (0.0, math.nan, 0.0, 0.0))
    with pytest.raises(ValueError, match="header"):
        schema.encode_around_send_time(1, -1, 0, (0.0,) * 4)
    with pytest.raises(ValueError, match="kind"):
        schema.encode(_message(LawSchema("mmt", "tool")))


@pytest.mark.parametrize(("payload", "reason"), [
    (_raw(LawSchema("mmt", "handle"), [0.0, 1.0, 2.0]), DropReason.MALFORMED),
    (_raw(LawSchema("mmt", "handle"), [0.0, 1.0, 2.0, 3.0, 4.0]), DropReason.MALFORMED),
    (_raw(LawSchema("mmt", "handle"), [0.0, math.nan, 2.0, 3.0]), DropReason.NON_FINITE),
    (_raw(LawSchema("mmt", "handle"), [0.0, math.inf, 2.0, 3.0]), DropReason.NON_FINITE),
    (_raw(LawSchema("mmt", "handle"), [0.0, "x", 2.0, 3.0]), DropReason.MALFORMED),
    (_raw(LawSchema("mmt", "handle"), [0.0, True, 2.0, 3.0]), DropReason.MALFORMED),
    (_raw(LawSchema("mmt", "handle"), [0.0] * 4, version=SCHEMA_VERSION + 1),
     DropReason.UNKNOWN_VERSION),
    (_raw(LawSchema("mmt", "handle"), [0.0] * 4, kind=law_kind("mmt", "tool")),
     DropReason.WRONG_KIND),
    (_raw(LawSchema("mmt", "handle"), [0.0] * 4, kind=law_kind("wave", "handle")),
     DropReason.WRONG_KIND),
    (_raw(LawSchema("mmt", "handle"), [0.0] * 4, seq=-1), DropReason.MALFORMED),
    (_raw(LawSchema("mmt", "handle"), [0.0] * 4, seq=1.0), DropReason.MALFORMED),
    (b"\x00\x01not msgpack", DropReason.MALFORMED),
    (msgpack.packb([SCHEMA_VERSION, 1]), DropReason.MALFORMED),
    (b"\x94" + b"\xcb" + bytes(8) * 2000, DropReason.MALFORMED),
], ids=["short", "long", "nan", "inf", "string", "bool", "version", "direction", "control",
        "negative-seq", "float-seq", "garbage", "no-header", "too-long"])
def test_every_bad_payload_is_refused_with_its_reason(payload: bytes,
                                                      reason: DropReason) -> None:
    with pytest.raises(DecodeError) as error:
        LawSchema("mmt", "handle").decode(payload, law_kind("mmt", "handle"))
    assert error.value.reason is reason


def test_a_program_message_and_a_law_message_do_not_mix() -> None:
    schema = LawSchema("four-channel", "handle")
    program = encode(HandleState(1, 1, 10**18, Flags(0), (0.0, 0.0), (0.0, 0.0)))
    with pytest.raises(DecodeError) as error:
        schema.decode(program, schema.kind)
    assert error.value.reason is DropReason.WRONG_KIND
    with pytest.raises(DecodeError) as error:
        decode(schema.encode(_message(schema)), KIND_HANDLE)
    assert error.value.reason is DropReason.WRONG_KIND


def _path(schema: LawSchema, injection: InjectionConfig | None = None,
          stale_after_s: float = 0.05) -> ReceivePath:
    return ReceivePath(schema.kind, injection or InjectionConfig(), np.random.default_rng(0),
                       stale_after_s, decoder=schema.decode)


def test_the_receive_path_counts_and_drops_bad_law_messages() -> None:
    schema = LawSchema("mmt", "tool")
    path = _path(schema)
    now = 10**18
    good = [schema.encode(_message(schema, seq, now)) for seq in (1, 2, 4)]
    for payload in good:
        assert not path.rejects_at_once(payload)  # the flood filter lets the largest through
        path.accept(payload, now)
    path.accept(_raw(schema, [0.0] * 7), now)  # wrong length
    path.accept(_raw(schema, [math.nan] * 8), now)  # non-finite
    path.accept(schema.encode(_message(schema, 2, now)), now)  # a replay: out of order
    path.accept(schema.encode(_message(schema, 5, now - 10**9)), now)  # a second old: stale
    path.accept(b"\xff" * 12, now)
    released = path.release(now)
    assert released is not None and released.seq == 4 and released.values == _values(schema)
    assert [m.seq for m in path.released] == [1, 2, 4]
    stats = path.stats()
    assert stats.dropped["malformed"] == 2 and stats.dropped["non_finite"] == 1
    assert stats.dropped["out_of_order"] == 1 and stats.dropped["stale"] == 1
    assert stats.delivered == 3 and stats.network_lost == 1  # seq 3 never came


def test_the_receive_path_injects_loss_on_law_messages() -> None:
    schema = LawSchema("wave", "handle")
    path = _path(schema, InjectionConfig(delay_s=0.01, loss_probability=0.5))
    now = 10**18
    for seq in range(1, 2001):
        path.accept(schema.encode(_message(schema, seq, now)), now)
    assert path.release(now) is None  # every one waits for its injected delay
    path.release(now + 10**7)
    stats = path.stats()
    lost = stats.dropped["injected_loss"]
    assert stats.delivered + lost == 2000 and 850 < lost < 1150


def test_random_payloads_never_raise() -> None:
    schema = LawSchema("four-channel", "tool")
    path = _path(schema)
    rng = np.random.default_rng(3)
    valid = schema.encode(_message(schema))
    for _ in range(2000):
        payload = bytearray(valid)
        for index in rng.integers(0, len(payload), 3):
            payload[index] = int(rng.integers(0, 256))
        path.accept(bytes(payload), 10**18)
    stats = path.stats()
    assert stats.received == 2000
    assert stats.delivered + sum(stats.dropped.values()) + path.pending <= 2000
