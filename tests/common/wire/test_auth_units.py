"""common/wire/auth.py pinned by value without a network: the key file's rules, the hello's
fields and tag, every reason a hello is refused (and which ones count), the session key
recomputed from its definition, and the data tags."""

from __future__ import annotations

import hashlib
import hmac
import os
import stat

import msgpack
import pytest

from haptic.common.config import ConfigError
from haptic.common.wire.auth import (
    HELLO_MAX_AGE_S,
    HELLO_PERIOD_S,
    KEY_BYTES,
    KIND_HELLO,
    NONCE_BYTES,
    TAG_BYTES,
    Hello,
    HelloError,
    SessionAuth,
    decode_hello,
    encode_hello,
    load_key_file,
    write_key_file,
)
from haptic.common.wire.messages import SCHEMA_VERSION

PSK = bytes(range(32))
NOW_NS = 1_700_000_000_000_000_000


def test_the_constants_are_the_documented_ones() -> None:
    assert (TAG_BYTES, KEY_BYTES, NONCE_BYTES, KIND_HELLO) == (16, 32, 16, 3)
    assert (HELLO_MAX_AGE_S, HELLO_PERIOD_S) == (5.0, 0.1)


def test_a_hello_is_frozen() -> None:
    import dataclasses

    hello = decode_hello(encode_hello("master", 1, bytes(16), NOW_NS, PSK), PSK)
    with pytest.raises(dataclasses.FrozenInstanceError):
        hello.epoch = 2  # type: ignore[misc]


def test_an_existing_key_file_is_made_private(tmp_path) -> None:
    path = tmp_path / "key"
    path.write_text("old")
    os.chmod(path, 0o644)
    write_key_file(path)
    assert stat.S_IMODE(os.stat(path).st_mode) == 0o600 and len(load_key_file(path)) == 32


@pytest.mark.parametrize("mode", [0o640, 0o604, 0o610, 0o601, 0o620, 0o602])
def test_any_group_or_other_bit_refuses_the_key_file(tmp_path, mode) -> None:
    path = write_key_file(tmp_path / "key")
    os.chmod(path, mode)
    with pytest.raises(ConfigError, match="readable by others") as error:
        load_key_file(path, "a.key")
    assert error.value.key == "a.key"
    assert f"mode {mode:o}" in str(error.value)


def test_a_written_key_file_is_64_hex_digits_mode_600_and_loads(tmp_path) -> None:
    path = write_key_file(tmp_path / "key")
    text = path.read_text()
    assert len(text.strip()) == 64 and text.endswith("\n")
    assert stat.S_IMODE(os.stat(path).st_mode) == 0o600
    assert load_key_file(path) == bytes.fromhex(text.strip())
    assert write_key_file(tmp_path / "other").read_text() != text  # random per call


@pytest.mark.parametrize("content", [b"ab" * 31, b"ab" * 33, b"zz" * 32, b"\xff\xfe" * 32])
def test_a_key_that_is_not_32_bytes_of_hex_is_refused(tmp_path, content) -> None:
    path = tmp_path / "key"
    path.write_bytes(content)
    os.chmod(path, 0o600)
    with pytest.raises(ConfigError, match="64 hex digits"):
        load_key_file(path)


def test_surrounding_whitespace_is_allowed(tmp_path) -> None:
    path = tmp_path / "key"
    path.write_text("  " + PSK.hex() + "\n\n")
    os.chmod(path, 0o600)
    assert load_key_file(path) == PSK


def test_a_hello_carries_its_fields_and_a_16_byte_tag() -> None:
    nonce = bytes(range(16))
    payload = encode_hello("slave", 7, nonce, NOW_NS, PSK)
    body = msgpack.packb([SCHEMA_VERSION, 3, 2, 7, nonce, NOW_NS, True], use_bin_type=True)
    assert payload == body + hmac.new(PSK, body, hashlib.sha256).digest()[:16]
    hello = decode_hello(payload, PSK)
    assert (hello.version, hello.side, hello.epoch, hello.nonce, hello.time_ns,
            hello.authenticated) == (SCHEMA_VERSION, "slave", 7, nonce, NOW_NS, True)
    plain = encode_hello("master", 7, nonce, NOW_NS, None)
    assert plain == msgpack.packb([SCHEMA_VERSION, 3, 1, 7, nonce, NOW_NS, False],
                                  use_bin_type=True)
    assert decode_hello(plain, None).authenticated is False


@pytest.mark.parametrize(("fields", "why"), [
    ([SCHEMA_VERSION, 3, 9, 7, bytes(16), NOW_NS, False], "bad field"),      # side code
    ([SCHEMA_VERSION, 3, [1], 7, bytes(16), NOW_NS, False], "bad field"),    # a list there
    ([SCHEMA_VERSION, 3, {"a": 1}, 7, bytes(16), NOW_NS, False], "bad field"),  # a map
    ([SCHEMA_VERSION, 3, True, 7, bytes(16), NOW_NS, False], "bad field"),   # a bool side
    ([SCHEMA_VERSION, 3, 1, True, bytes(16), NOW_NS, False], "bad field"),   # a bool epoch
    ([SCHEMA_VERSION, 3, 1, 7, bytes(16), True, False], "bad field"),        # a bool time
    ([SCHEMA_VERSION, 3, 1, 7, bytes(16), -1, False], "bad field"),          # time < 0
    ([SCHEMA_VERSION, 3.0, 1, 7, bytes(16), NOW_NS, False], "not a hello"),  # a float kind
    ([SCHEMA_VERSION, 3, 1, -1, bytes(16), NOW_NS, False], "bad field"),     # epoch < 0
    ([SCHEMA_VERSION, 3, 1, 2**32, bytes(16), NOW_NS, False], "bad field"),  # epoch too big
    ([SCHEMA_VERSION, 3, 1, 1.0, bytes(16), NOW_NS, False], "bad field"),    # epoch not int
    ([SCHEMA_VERSION, 3, 1, 7, bytes(15), NOW_NS, False], "bad field"),      # short nonce
    ([SCHEMA_VERSION, 3, 1, 7, "x" * 16, NOW_NS, False], "bad field"),       # nonce not bytes
    ([SCHEMA_VERSION, 3, 1, 7, bytes(16), 1.5, False], "bad field"),         # time not int
    ([SCHEMA_VERSION, 3, 1, 7, bytes(16), NOW_NS, 1], "bad field"),          # flag not bool
    ([SCHEMA_VERSION, 3, 1, 7, bytes(16), NOW_NS], "wrong shape"),
    ([SCHEMA_VERSION, 3, 1, 7, bytes(16), NOW_NS, False, 0], "bad field"),   # control int
    ([SCHEMA_VERSION, 3, 1, 7, bytes(16), NOW_NS, False, "wave", 0], "wrong shape"),
    ([SCHEMA_VERSION, 1, 1, 7, bytes(16), NOW_NS, False], "not a hello"),
    ([SCHEMA_VERSION], "not a hello"),
    ({"a": 1}, "not a hello"),
])
def test_malformed_hellos_are_refused_with_their_reason(fields, why) -> None:
    with pytest.raises(HelloError, match=why):
        decode_hello(msgpack.packb(fields, use_bin_type=True), None)


def test_edges_of_a_hello_decode() -> None:
    ok = msgpack.packb([SCHEMA_VERSION, 3, 1, 2**32 - 1, bytes(16), NOW_NS, False],
                       use_bin_type=True)
    assert decode_hello(ok, None).epoch == 2**32 - 1
    assert decode_hello(ok[:0] + ok, None).epoch == 2**32 - 1
    with pytest.raises(HelloError, match="too long"):
        decode_hello(ok + bytes(257 - len(ok)), None)
    with pytest.raises(HelloError, match="trailing bytes"):
        decode_hello(ok + b"x", None)
    with pytest.raises(HelloError, match="not msgpack"):
        decode_hello(b"\xc1", None)
    other = msgpack.packb([SCHEMA_VERSION + 1, 3, "anything"], use_bin_type=True)
    assert decode_hello(other, PSK) == Hello(SCHEMA_VERSION + 1, "", 0, b"", 0, False)
    assert decode_hello(msgpack.packb(["v", 3], use_bin_type=True), None) == Hello(
        -1, "", 0, b"", 0, False)
    assert decode_hello(msgpack.packb([float(SCHEMA_VERSION), 3, 1], use_bin_type=True),
                        None) == Hello(-1, "", 0, b"", 0, False)  # a float is not a version
    # 256 bytes is not too long (it fails on what follows the body instead)
    with pytest.raises(HelloError, match="trailing bytes"):
        decode_hello(ok + bytes(256 - len(ok)), None)
    zero = msgpack.packb([SCHEMA_VERSION, 3, 2, 0, bytes(16), NOW_NS, False], use_bin_type=True)
    assert decode_hello(zero, None).epoch == 0
    # the time stamp's whole range, 0 to 2**63 - 1 ns, and not one past it
    for time_ns in (0, 2**63 - 1):
        edge = msgpack.packb([SCHEMA_VERSION, 3, 2, 7, bytes(16), time_ns, False],
                             use_bin_type=True)
        assert decode_hello(edge, None).time_ns == time_ns
    past = msgpack.packb([SCHEMA_VERSION, 3, 2, 7, bytes(16), 2**63, False], use_bin_type=True)
    with pytest.raises(HelloError, match="bad field"):
        decode_hello(past, None)


def test_an_authenticated_hello_needs_a_tag_that_verifies() -> None:
    payload = encode_hello("master", 1, bytes(16), NOW_NS, PSK)
    for bad in (payload[:-1], payload + b"\0", payload[:-1] + bytes([payload[-1] ^ 0x80])):
        with pytest.raises(HelloError, match="tag does not verify"):
            decode_hello(bad, PSK)
    # without a psk it decodes unverified (the caller reports the mismatch)
    assert decode_hello(payload, None).authenticated



def test_a_hello_may_carry_the_lane_law_it_runs_as_an_8th_field() -> None:
    nonce = bytes(range(16))
    plain = encode_hello("master", 7, nonce, NOW_NS, None, "four-channel-tdpa")
    assert plain == msgpack.packb([SCHEMA_VERSION, 3, 1, 7, nonce, NOW_NS, False,
                                   "four-channel-tdpa"], use_bin_type=True)
    assert decode_hello(plain, None).control == "four-channel-tdpa"
    assert decode_hello(encode_hello("master", 7, nonce, NOW_NS, None), None).control is None
    longest = "a-0" * 10 + "z9"  # 32 characters
    assert decode_hello(encode_hello("slave", 7, nonce, NOW_NS, None, longest),
                        None).control == longest
    # the tag covers the 8th field: its body is the whole msgpack array
    tagged = encode_hello("slave", 7, nonce, NOW_NS, PSK, "wave")
    body = msgpack.packb([SCHEMA_VERSION, 3, 2, 7, nonce, NOW_NS, True, "wave"],
                         use_bin_type=True)
    assert tagged == body + hmac.new(PSK, body, hashlib.sha256).digest()[:16]
    hello = decode_hello(tagged, PSK)
    assert (hello.side, hello.authenticated, hello.control) == ("slave", True, "wave")
    swapped = msgpack.packb([SCHEMA_VERSION, 3, 2, 7, nonce, NOW_NS, True, "mmt"],
                            use_bin_type=True) + tagged[len(body):]
    with pytest.raises(HelloError, match="tag does not verify"):
        decode_hello(swapped, PSK)
    untagged_control = msgpack.packb([SCHEMA_VERSION, 3, 2, 7, nonce, NOW_NS, True],
                                     use_bin_type=True) + tagged[len(body):]
    with pytest.raises(HelloError, match="tag does not verify"):
        decode_hello(untagged_control, PSK)
    master = SessionAuth(PSK, "master", 11)
    assert decode_hello(master.hello(NOW_NS, "mmt"), PSK).control == "mmt"
    assert decode_hello(master.hello(NOW_NS), PSK).control is None


@pytest.mark.parametrize("control", [
    b"wave",          # bytes, not a str
    7,                # an int
    None,             # nil is not "no control": that is 7 fields
    ["wave"],         # a list
    "",               # empty
    "a" * 33,         # too long
    "Wave",           # upper case
    "wave_2",         # an underscore
    "wave ",          # a space
    "w\u00e4ve",      # not ASCII
    "wave\n",         # a trailing newline
])
def test_a_hello_whose_8th_field_is_not_a_control_name_is_refused(control) -> None:
    fields = [SCHEMA_VERSION, 3, 1, 7, bytes(16), NOW_NS, False, control]
    with pytest.raises(HelloError, match="bad field"):
        decode_hello(msgpack.packb(fields, use_bin_type=True), None)
    if type(control) is str:
        with pytest.raises(ValueError, match="a-z0-9-"):
            encode_hello("master", 7, bytes(16), NOW_NS, None, control)


def pair() -> tuple[SessionAuth, SessionAuth]:
    master, slave = SessionAuth(PSK, "master", 11), SessionAuth(PSK, "slave", 22)
    assert slave.accept_hello(decode_hello(master.hello(NOW_NS), PSK), NOW_NS)
    assert master.accept_hello(decode_hello(slave.hello(NOW_NS), PSK), NOW_NS)
    return master, slave


def test_the_session_key_is_the_documented_hmac_and_both_sides_agree() -> None:
    master, slave = pair()
    assert master.paired and slave.paired and master.pairings == slave.pairings == 1
    key = hmac.new(PSK, b"haptic-teleop/2/session" + master.nonce + slave.nonce
                   + (11).to_bytes(4, "big") + (22).to_bytes(4, "big"), hashlib.sha256).digest()
    body = b"some message body"
    expected = hmac.new(key, body, hashlib.sha256).digest()[:16]
    assert master.tag(body) == slave.tag(body) == expected
    assert slave.verify(body + expected) == body
    assert master.tag(body) == expected  # the running MAC is copied, never consumed


def test_verify_refuses_tampering_short_payloads_and_an_unpaired_side() -> None:
    master, slave = pair()
    body = b"x" * 40
    tagged = body + master.tag(body)
    assert slave.verify(tagged) == body
    assert slave.verify(tagged[:-1] + bytes([tagged[-1] ^ 1])) is None
    assert slave.verify(bytes([tagged[0] ^ 1]) + tagged[1:]) is None
    assert slave.verify(tagged[-TAG_BYTES:]) is None          # a tag and no body
    assert slave.verify(master.tag(b"")) is None              # even the empty body's tag
    assert slave.verify(b"y" + master.tag(b"y")) == b"y"      # one byte of body is enough
    assert SessionAuth(PSK, "slave", 22).verify(tagged) is None  # not paired
    with pytest.raises(ValueError, match="32 bytes"):
        SessionAuth(PSK[:31], "master", 1)


def test_hello_refusals_and_what_counts_as_rejected() -> None:
    slave = SessionAuth(PSK, "slave", 22)
    master = SessionAuth(PSK, "master", 11)
    # another slave's hello: refused and counted
    assert not slave.accept_hello(decode_hello(SessionAuth(PSK, "slave", 5).hello(NOW_NS),
                                               PSK), NOW_NS)
    assert slave.rejected_hellos == 1
    # an unauthenticated hello: refused and counted
    assert not slave.accept_hello(decode_hello(encode_hello("master", 11, bytes(16), NOW_NS,
                                                            None), None), NOW_NS)
    assert slave.rejected_hellos == 2
    # exactly the age limit is accepted; a nanosecond older or newer is not, and is counted
    limit_ns = int(HELLO_MAX_AGE_S * 1e9)
    stale = decode_hello(master.hello(NOW_NS - limit_ns - 1), PSK)
    assert not slave.accept_hello(stale, NOW_NS) and slave.rejected_hellos == 3
    future = decode_hello(master.hello(NOW_NS + limit_ns + 1), PSK)
    assert not slave.accept_hello(future, NOW_NS) and slave.rejected_hellos == 4
    assert slave.accept_hello(decode_hello(master.hello(NOW_NS - limit_ns), PSK), NOW_NS)
    assert slave.peer_epoch == 11 and slave.pairings == 1
    # the same time again (a replay) and an older one: refused and counted
    again = decode_hello(master.hello(NOW_NS - limit_ns), PSK)
    assert not slave.accept_hello(again, NOW_NS) and slave.rejected_hellos == 5
    older = decode_hello(master.hello(NOW_NS - limit_ns - 5), PSK)
    assert not slave.accept_hello(older, NOW_NS - 10) and slave.rejected_hellos == 6
    # a later hello of the same run: accepted in time, no new pairing
    assert not slave.accept_hello(decode_hello(master.hello(NOW_NS), PSK), NOW_NS)
    assert slave.pairings == 1 and slave.rejected_hellos == 6
    # the same epoch with a new nonce is a new run: re-paired
    rerun = SessionAuth(PSK, "master", 11)
    assert slave.accept_hello(decode_hello(rerun.hello(NOW_NS + 1), PSK), NOW_NS + 1)
    assert slave.pairings == 2 and slave.peer.nonce == rerun.nonce


def test_the_first_hello_may_carry_any_time_after_zero() -> None:
    slave = SessionAuth(PSK, "slave", 22)
    assert slave.accept_hello(decode_hello(SessionAuth(PSK, "master", 1).hello(1), PSK), 1)


def test_another_run_with_the_same_time_stamp_is_not_a_re_pairing() -> None:
    slave = SessionAuth(PSK, "slave", 22)
    assert slave.accept_hello(decode_hello(SessionAuth(PSK, "master", 1).hello(NOW_NS), PSK),
                              NOW_NS)
    twin = decode_hello(SessionAuth(PSK, "master", 2).hello(NOW_NS), PSK)
    assert not slave.accept_hello(twin, NOW_NS) and slave.peer_epoch == 1


def test_before_pairing_there_is_no_peer() -> None:
    side = SessionAuth(PSK, "master", 1)
    assert side.peer_side == "slave" and SessionAuth(PSK, "slave", 1).peer_side == "master"
    assert side.peer_epoch is None and not side.paired
    assert (side.pairings, side.rejected_hellos) == (0, 0)
    assert len(side.nonce) == 16 and side.nonce != SessionAuth(PSK, "master", 1).nonce
