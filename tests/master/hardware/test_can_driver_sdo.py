"""The CAN driver's SDO exchanges at unit level: the CiA 301 abort texts, against a
scripted peer (lost requests, deadlines on a clock of the test's own, replies that are not
the exchange's, aborts) and supervision frames that arrive meanwhile."""

from __future__ import annotations

import time

import can
import pytest

from haptic.common.config import load_config
from haptic.master.hardware import cia402, sdo_client
from haptic.master.hardware.can_driver import CanHandleDriver
from haptic.master.hardware.cia402 import DriveState
from haptic.master.hardware.drive_device import load_drive_dictionary
from haptic.master.hardware.interface import HardwareError
from haptic.master.hardware.sdo_client import abort_text
from haptic.master.settings import master_settings
from tests.master.hardware.can_driver_helpers import (
    HEARTBEAT_BASE,
    bare_driver,
    inactive_rig,
)

#: CiA 301's SDO abort codes the driver names, with their meanings (CiA 301, table 22).
ABORT_MEANINGS = {
    0x05040001: "command specifier not valid", 0x06010000: "unsupported access",
    0x06010001: "write-only object", 0x06010002: "read-only object",
    0x06020000: "object does not exist", 0x06040041: "object cannot be mapped to the PDO",
    0x06040042: "mapping exceeds the PDO length", 0x06040043: "parameter incompatibility",
    0x06070010: "data type length mismatch", 0x06090011: "sub-index does not exist",
    0x06090030: "value out of range", 0x08000000: "general error",
    0x08000020: "cannot be stored or used now", 0x08000022: "not in the present device state",
}


@pytest.mark.parametrize(("code", "meaning"), [*ABORT_MEANINGS.items(),
                                               (0x12345678, "see CiA 301"),
                                               (0x06090031, "see CiA 301")])
def test_the_sdo_abort_texts(code: int, meaning: str) -> None:
    """Known CiA 301 abort codes get their meaning, any other the pointer to the standard."""
    assert abort_text(code) == meaning


# --- SDO exchanges against a scripted peer -----------------------------------------------


class _SdoPeer:
    """A second bus member that answers each SDO request to node 1 with the frames
    ``answer(request_number, request)`` gives, (id, data) each, data None for a remote
    frame (none: the request is lost)."""

    def __init__(self, channel: str, answer) -> None:
        self.requests: list[bytes] = []
        self._answer = answer
        self._bus = can.Bus(interface="virtual", channel=channel)
        self._notifier = can.Notifier(self._bus, [self._on_message], timeout=0.01)

    def _on_message(self, message: can.Message) -> None:
        if message.arbitration_id != cia402.SDO_RX_BASE + 1:
            return
        self.requests.append(bytes(message.data))
        for frame_id, data in self._answer(len(self.requests), bytes(message.data)):
            self._bus.send(can.Message(arbitration_id=frame_id, is_extended_id=False,
                                       data=data, is_remote_frame=True, dlc=1)
                           if data is None else
                           can.Message(arbitration_id=frame_id, data=data,
                                       is_extended_id=False))

    def close(self) -> None:
        self._notifier.stop()
        self._bus.shutdown()


def _sdo_driver(pdo_timeout_s: float = 0.01) -> tuple[CanHandleDriver, str]:
    driver, channel = bare_driver()
    # the SDO deadline is enable_timeout_cycles (200) PDO timeouts
    driver.sdo.deadline_s = pdo_timeout_s * driver.settings.enable_timeout_cycles
    return driver, channel


_TX = cia402.SDO_TX_BASE + 1


def _exchange(answer, action, pdo_timeout_s: float = 0.01):
    """Run ``action(driver, dictionary)`` against a peer answering with ``answer``; the
    result (or the HardwareError), the driver and the requests the peer saw."""
    driver, channel = _sdo_driver(pdo_timeout_s)
    peer = _SdoPeer(channel, answer)
    dictionary = load_drive_dictionary("", 1)
    try:
        try:
            result = action(driver, dictionary)
        except HardwareError as error:
            result = error
        return result, driver, peer.requests
    finally:
        peer.close()
        driver._close_bus()


def test_a_lost_sdo_request_is_sent_again_and_counted() -> None:
    """No reply within SDO_RESEND_S: the same request again, counted in ``sdo_resends``."""
    def second_only(number: int, request: bytes):
        if number < 2:
            return []
        return [(_TX, cia402.sdo_upload_response(dictionary_1017, 250))]

    dictionary_1017 = load_drive_dictionary("", 1)[0x1017]
    result, driver, requests = _exchange(
        second_only, lambda d, od: d.sdo.read(1, od[0x1017], "x drive"))
    assert result == 250
    assert len(requests) >= 2 and set(requests) == {requests[0]}
    assert driver.sdo_resends == len(requests) - 1


def test_no_sdo_reply_by_the_deadline_is_one_hardware_error() -> None:
    """Nothing answers: the request is sent again every SDO_RESEND_S until the deadline
    (``pdo_timeout_s`` x ``enable_timeout_cycles``: 0.4 s here, so once), then an error
    naming the node and the object."""
    result, driver, requests = _exchange(
        lambda n, r: [], lambda d, od: d.sdo.read(1, od[0x1017], "x drive"),
        pdo_timeout_s=0.002)
    assert str(result) == ("x drive read: no SDO reply from node 1 for 0x1017:00 (Producer "
                           "heartbeat time)")
    assert len(requests) == 2 and driver.sdo_resends == 1


def test_an_sdo_exchange_skips_what_is_not_its_reply() -> None:
    """Skipped while waiting: a reply of another node, one that is not 8 bytes, a reply
    for another object; taken: the reply for the object, of which only the variable's size
    counts (UNSIGNED16 here)."""
    def noisy(number: int, request: bytes):
        return [(cia402.SDO_TX_BASE + 2, bytes([0x4B, 0x17, 0x10, 0, 1, 0, 0, 0])),
                (_TX, b"\x4b\x17\x10"),
                (_TX, bytes([0x4B, 0x18, 0x10, 0, 2, 0, 0, 0])),
                (_TX, bytes([0x43, 0x17, 0x10, 0, 0x34, 0x12, 0xFF, 0xFF]))]

    result, driver, requests = _exchange(
        noisy, lambda d, od: d.sdo.read(1, od[0x1017], "x drive"))
    assert result == 0x1234 and len(requests) == 1 and driver.late_frames == 0


def test_an_sdo_abort_names_the_object_and_its_code() -> None:
    def abort(number: int, request: bytes):
        return [(_TX, cia402.sdo_abort(0x1017, 0, 0x06090030))]

    result, _, _ = _exchange(abort, lambda d, od: d.sdo.write(1, od[0x1017], 9, "x drive"))
    assert str(result) == ("x drive write: SDO abort 0x06090030 (value out of range) on "
                           "0x1017:00 (Producer heartbeat time)")


@pytest.mark.parametrize(("command", "named"), [
    (0x41, "0x41"), (0x60, "0x60"), (0x4F, None), (0x4B, None), (0x43, None), (0x42, None)])
def test_an_sdo_read_takes_only_an_expedited_upload(command: int, named: str | None) -> None:
    """An upload reply must be expedited (0x4?, bit 1 set); a segmented one (0x41) or a
    download reply (0x60) is refused, naming the command."""
    def reply(number: int, request: bytes):
        return [(_TX, bytes([command, 0x17, 0x10, 0, 0x64, 0, 0, 0]))]

    result, _, _ = _exchange(reply, lambda d, od: d.sdo.read(1, od[0x1017], "x drive"))
    if named is None:
        assert result == 100
    else:
        assert str(result) == (f"x drive: 0x1017:00 answered with SDO command {named}, not an "
                               "expedited upload")


@pytest.mark.parametrize("command", [0x43, 0x40, 0x61])
def test_an_sdo_write_takes_only_a_download_reply(command: int) -> None:
    def reply(number: int, request: bytes):
        return [(_TX, bytes([command, 0x17, 0x10, 0, 0, 0, 0, 0]))]

    result, _, _ = _exchange(reply, lambda d, od: d.sdo.write(1, od[0x1017], 9, "x drive"))
    assert str(result) == (f"x drive: unexpected SDO reply 0x{command:02X} to the write of "
                           "0x1017:00")
    result, _, requests = _exchange(
        lambda n, r: [(_TX, cia402.sdo_download_response(0x1017, 0))],
        lambda d, od: d.sdo.write(1, od[0x1017], 9, "x drive"))
    assert result is None and requests == [cia402.sdo_download_request(
        load_drive_dictionary("", 1)[0x1017], 9)]


def test_supervision_frames_during_an_sdo_exchange_are_kept_for_the_next_read() -> None:
    """An EMCY while waiting for an SDO reply is logged and kept as a fault; a heartbeat
    notes the drive as heard, whatever state it reports (not a fault while configuring)."""
    def with_emcy(number: int, request: bytes):
        return [(cia402.EMCY_BASE + 1, cia402.emcy_frame(0x5530)),
                (HEARTBEAT_BASE + 2, b"\x7f"),
                (_TX, cia402.sdo_upload_response(
                    load_drive_dictionary("", 1)[0x1017], 5))]

    before = time.monotonic()
    result, driver, _ = _exchange(with_emcy, lambda d, od: d.sdo.read(1, od[0x1017], "x"))
    assert result == 5
    assert driver.emcy_log == [("x", 0x5530)]
    assert driver._pending_faults == ["x drive EMCY error code 0x5530 (register 0x01)"]
    assert driver.heartbeats.seen_s[1] >= before and driver.heartbeats.seen_s[0] == 0.0


def test_remote_frames_on_the_supervision_ids_during_an_sdo_exchange_are_ignored() -> None:
    """A remote frame on a drive's EMCY or heartbeat COB-ID (a node guarding request: the
    master's own, or another master's) is neither an EMCY nor the drive's heartbeat."""
    def with_requests(number: int, request: bytes):
        return [(cia402.EMCY_BASE + 1, None), (HEARTBEAT_BASE + 2, None),
                (_TX, cia402.sdo_upload_response(load_drive_dictionary("", 1)[0x1017], 5))]

    result, driver, _ = _exchange(with_requests, lambda d, od: d.sdo.read(1, od[0x1017], "x"))
    assert result == 5
    assert driver.emcy_log == [] and driver._pending_faults == []
    assert driver.heartbeats.seen_s == [0.0, 0.0]


def test_a_drive_that_faults_silently_once_enabled_is_reset_directly(monkeypatch) -> None:
    """A drive already enabled that faults without an EMCY while the other drive is still
    being enabled: its next step is the fault reset itself (bit 7 was low: the controlword
    before was enable operation), then the sequence again."""
    with inactive_rig() as hardware:
        hardware.configure()
        hardware.rig.inject_drive_fault(1, 0x2310)  # the y drive one step behind
        hardware.read()
        driver = hardware.driver
        send_rpdo = driver.pdos.send_rpdo
        x_words: list[int] = []

        def fault_x_when_enabled(axis: int, controlword: int) -> None:
            send_rpdo(axis, controlword)
            if axis == 0:
                x_words.append(controlword)
                if len(x_words) == 4:  # x enabled after three steps, y not yet
                    with hardware.rig._lock:
                        hardware.rig.drives[0].state = DriveState.FAULT  # no EMCY

        monkeypatch.setattr(driver.pdos, "send_rpdo", fault_x_when_enabled)
        hardware.activate()
        assert driver.drive_states == (DriveState.OPERATION_ENABLED,) * 2
        assert x_words == [cia402.CW_SHUTDOWN, cia402.CW_SWITCH_ON, cia402.CW_ENABLE_OPERATION,
                           cia402.CW_ENABLE_OPERATION, cia402.CW_FAULT_RESET,
                           cia402.CW_SHUTDOWN, cia402.CW_SWITCH_ON,
                           cia402.CW_ENABLE_OPERATION][:len(x_words)]
        assert len(x_words) >= 8


class _SilentBus:
    """A bus on which nothing answers, with its own clock: each receive waits exactly its
    timeout (s) of that clock."""

    def __init__(self) -> None:
        self.now_s = 100.0
        self.sent: list[bytes] = []
        self.waits_s: list[float] = []

    def monotonic(self) -> float:
        return self.now_s

    def recv(self, timeout: float) -> None:
        self.waits_s.append(timeout)
        self.now_s += timeout

    def send(self, message: can.Message) -> None:
        self.sent.append(bytes(message.data))


@pytest.mark.parametrize(("deadline_s", "requests"), [(0.2, 1), (0.6, 3), (0.5, 2)])
def test_an_sdo_exchange_waits_no_longer_than_its_deadline(monkeypatch, deadline_s: float,
                                                           requests: int) -> None:
    """With nothing answering, the exchange waits until its deadline exactly, never beyond
    it (not until a resend due later), sending the request again every SDO_RESEND_S (0.25 s)
    before it."""
    bus = _SilentBus()
    monkeypatch.setattr(sdo_client, "time", bus)  # the SDO client's clock is the bus's
    driver = CanHandleDriver(master_settings(load_config()).can,
                             {"interface": "virtual", "channel": "unused"},
                             deadline_s / 200, 0.00054)  # enable_timeout_cycles = 200
    driver.frames.bus = bus
    dictionary = load_drive_dictionary("", 1)
    start = bus.now_s
    with pytest.raises(HardwareError, match=r"^x: no SDO reply from node 1 for 0x1017:00"):
        driver.sdo.exchange(1, cia402.sdo_upload_request(dictionary[0x1017]),
                             dictionary[0x1017], "x")
    assert bus.now_s - start == pytest.approx(deadline_s, abs=1e-9)
    assert len(bus.sent) == requests and driver.sdo_resends == requests - 1
