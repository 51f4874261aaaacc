"""The ``sim`` backend: the CAN driver against the rig's devices in their own process
(``haptic-rig-sim``), and the emulator's frame handling and command line.

Every emulator a test starts is ended by its own PID and reaped (the backend's cleanup, or
the test's ``finally``); every wait is bounded. Nothing here asserts a timing figure.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import can
import numpy as np
import pytest

from haptic.common.config import load_config, override, to_toml
from haptic.common.model.teleop import model_from_config
from haptic.master.hardware import cia402
from haptic.master.hardware.can_driver import CanHandleDriver
from haptic.master.hardware.canopen_setup import configuration_steps
from haptic.master.hardware.cia402 import DriveState
from haptic.master.hardware.drive_device import load_drive_dictionary
from haptic.master.hardware.interface import HardwareError, LifecycleState, create_hardware
from haptic.master.node import MasterNode
from haptic.master.settings import master_settings
from haptic.master.simulated_rig.can_devices import (
    OPERATOR_DISPLAY_ID,
    SimulatedCanRig,
    decode_operator_display,
    encode_operator_display,
)
from haptic.master.simulated_rig.cli import main as rig_sim_main
from haptic.master.simulated_rig.rig_emulator import READY_PREFIX, EmulatedRigHardware
from haptic.master.standalone import run_master
from tests.helpers.programs import Program, Programs, python_module, run_to_end

#: Cap on waiting for anything a child does, s.
WAIT_S = 40.0


def _config(operator: str = "constant:fx=0,fy=0", **overrides: object) -> dict:
    config = override(load_config(), "master.sim.operator", operator)
    # The heartbeats both ways are wall-clock supervision (test_can_commissioning.py and the
    # emulator's own test below). Here the master's driver runs in the test process, and a
    # pause of that process beyond the shipped 0.3 s consumer time (a gen-2 collection of a
    # long test session's heap; a 0.3 s collection every 0.15 s faulted 6 of 8 such runs
    # with EMCY 0x8130) latches the drives in Fault, as test_can_devices.py explains.
    config = override(config, "master.can.heartbeat_timeout_s", 5.0)
    for key, value in overrides.items():
        config = override(config, key.replace("__", "."), value)
    return config


def _node(config: dict) -> MasterNode:
    return MasterNode.from_model(model_from_config(config), master_settings(config).safety)


def _reaped(process: subprocess.Popen | None) -> bool:
    """The child has ended and was waited for (its PID released)."""
    if process is None or process.returncode is None:
        return False
    try:
        os.waitpid(process.pid, os.WNOHANG)
    except ChildProcessError:
        return True
    return False


# --- the frame logic: an answer prepared on the display frame is the answer --------------


class _RecordingBus:
    """Stands in for a bus: keeps what the devices send."""

    def __init__(self) -> None:
        self.sent: list[tuple[int, bytes]] = []

    def send(self, message: can.Message) -> None:
        self.sent.append((message.arbitration_id, bytes(message.data)))


def _frame(frame_id: int, data: bytes = b"", extended: bool = False) -> can.Message:
    return can.Message(arbitration_id=frame_id, data=data, is_extended_id=extended)


def _rpdo(node: int, controlword: int, target: int) -> can.Message:
    return _frame(cia402.RPDO1_BASE + node,
                  cia402.encode_pdo(cia402.RPDO1_MAPPING, (controlword, target)))


def _enabled_rig(config: dict) -> tuple[SimulatedCanRig, _RecordingBus]:
    """Devices started over NMT and SDO and enabled with the CiA 402 sequence, by frames."""
    rig = SimulatedCanRig.from_config(config, "frames")
    bus = _RecordingBus()
    rig.attach(bus)  # type: ignore[arg-type]
    rig.handle_message(_frame(cia402.NMT_COB_ID, bytes([cia402.NMT_START, 0])))
    for node in rig.settings.node_ids:  # the driver's configuration sequence, by SDO frames
        for step in configuration_steps(load_drive_dictionary(None, node), node, 540e-6, 127,
                                        0.1, 0.3, 0.0, 20000, "drive"):
            rig.handle_message(_frame(cia402.SDO_RX_BASE + node, cia402.sdo_download_request(
                step.variable, step.value)))
    for controlword in (cia402.CW_SHUTDOWN, cia402.CW_SWITCH_ON, cia402.CW_ENABLE_OPERATION):
        for node in rig.settings.node_ids:
            rig.handle_message(_rpdo(node, controlword, 0))
        rig.handle_message(_frame(cia402.SYNC_COB_ID))
    assert [d.state for d in rig.drives] == [DriveState.OPERATION_ENABLED] * 2
    return rig, bus


def test_the_operator_display_payload_round_trips() -> None:
    force = np.array([3.25, -0.5])
    assert len(encode_operator_display(force)) == 8
    np.testing.assert_array_equal(decode_operator_display(encode_operator_display(force)), force)
    with pytest.raises(ValueError, match="8"):
        decode_operator_display(b"\x00" * 6)


def test_an_answer_prepared_on_the_display_frame_equals_one_computed_at_the_sync() -> None:
    """Frames in the order the sim backend sends them (RPDOs, display, SYNC), the answer
    prepared ahead in between (as the serving loop does when no frame waits), with sensor
    noise, a regulating operator and inputs that change after it now and then (the prepared
    answer is taken back, and sometimes prepared anew): the same frames and samples as
    devices given the tool force directly and computing every answer at the SYNC."""
    config = _config("regulate:fx=2,kp=0.5,ki=4,lag=0.02,max=10",
                     master__sim__force_noise_std_N=0.05, master__sim__seed=3)
    prepared, prepared_bus = _enabled_rig(config)
    direct, direct_bus = _enabled_rig(config)
    nodes = prepared.settings.node_ids
    prepared_bus.sent.clear()
    direct_bus.sent.clear()
    late_inputs = prepared_anew = 0
    for cycle in range(300):
        force = np.array([0.01 * cycle, -0.5])
        target = 4 * cycle
        for rig in (prepared, direct):
            for node in nodes:
                rig.handle_message(_rpdo(node, cia402.CW_ENABLE_OPERATION, target))
        prepared.handle_message(_frame(OPERATOR_DISPLAY_ID, encode_operator_display(force),
                                       extended=True))
        direct.set_tool_force(decode_operator_display(encode_operator_display(force)))
        assert prepared.prepare_ahead()  # the serving loop, idle before the SYNC
        assert not direct.prepare_ahead()  # no display frame: nothing to prepare ahead
        if cycle % 7 == 3:  # an input after the display frame: the prepared answer goes
            late_inputs += 1
            for rig in (prepared, direct):
                rig.handle_message(_rpdo(nodes[1], cia402.CW_ENABLE_OPERATION, -target))
            if cycle % 14 == 3:  # idle again before the SYNC: prepared anew
                assert prepared.prepare_ahead()
                prepared_anew += 1
        if cycle == 151:  # a fault injected between the display frame and the SYNC
            for rig in (prepared, direct):
                rig.inject_drive_fault(0, 0x5530)
        for rig in (prepared, direct):
            rig.handle_message(_frame(cia402.SYNC_COB_ID))
        for name in ("handle_position_m", "handle_force_measured_N",
                     "operator_intent_force_N"):
            np.testing.assert_array_equal(getattr(prepared.last_sample, name),
                                          getattr(direct.last_sample, name))
    assert prepared_bus.sent == direct_bus.sent
    assert any(frame_id == cia402.EMCY_BASE + nodes[0] for frame_id, _ in prepared_bus.sent)
    assert late_inputs > prepared_anew > 0
    assert prepared.prepared_syncs == 300 - late_inputs + prepared_anew - 1
    assert direct.prepared_syncs == 0
    assert not prepared.errors and not direct.errors
    moved = prepared.last_sample.operator_intent_force_N[0, 0]
    assert moved != 2.0  # the operator reacted to the displayed force


def test_the_serving_loop_prepares_ahead_only_when_idle(tmp_path) -> None:
    """On a ``unix_datagram`` bus: a display frame that comes alone is followed by an idle
    wait, in which the answer is prepared (the SYNC sends it); a display frame in its SYNC's
    own datagram (the sim backend's cycle) is answered at the SYNC, with no copies made to
    take a step back. The answers reach the bus either way."""
    rig, _ = _enabled_rig(_config())
    emulator_bus = can.Bus(interface="unix_datagram", channel=str(tmp_path))
    master_bus = can.Bus(interface="unix_datagram", channel=str(tmp_path))
    stop = threading.Event()
    thread = threading.Thread(target=rig.serve, args=(stop.is_set, 0.05), daemon=True)
    try:
        rig.attach(emulator_bus)
        thread.start()
        display = _frame(OPERATOR_DISPLAY_ID, encode_operator_display(np.array([1.0, 0.0])),
                         extended=True)
        syncs, prepared = rig.sync_count, rig.prepared_syncs

        answer_ids = {device.tpdo.cob_id for device in rig.devices} | {rig.codec.frame_id}

        def answered(count: int) -> set[int]:
            """The answer frames' ids seen once the SYNC was answered (heartbeats go on)."""
            seen: set[int] = set()
            deadline = time.monotonic() + WAIT_S
            while (rig.sync_count < count or not answer_ids <= seen) and (
                    time.monotonic() < deadline):
                frame = master_bus.recv(0.05)
                if frame is not None:
                    seen.add(frame.arbitration_id)
            return seen

        master_bus.send(display)
        deadline = time.monotonic() + WAIT_S
        while rig._prepared is None and time.monotonic() < deadline:  # idle: prepared
            time.sleep(0.005)
        master_bus.send(_frame(cia402.SYNC_COB_ID))
        first = answered(syncs + 1)
        assert (rig.sync_count, rig.prepared_syncs) == (syncs + 1, prepared + 1)
        master_bus.send_burst([display, _frame(cia402.SYNC_COB_ID)])  # one datagram
        second = answered(syncs + 2)
        assert (rig.sync_count, rig.prepared_syncs) == (syncs + 2, prepared + 1)
        assert answer_ids <= first and answer_ids <= second  # both TPDOs and the sensor
        assert not rig.errors
    finally:
        stop.set()
        thread.join(timeout=5.0)
        emulator_bus.shutdown()
        master_bus.shutdown()
    assert not thread.is_alive()


def test_a_preparation_that_raises_is_recorded_and_serving_goes_on(monkeypatch) -> None:
    rig, _ = _enabled_rig(_config())
    rig.handle_message(_frame(OPERATOR_DISPLAY_ID, encode_operator_display(np.zeros(2)),
                              extended=True))

    def broken(*args: object, **kwargs: object) -> None:
        raise RuntimeError("model step failed")

    monkeypatch.setattr(rig, "_prepare_sync", broken)
    assert rig.prepare_ahead() is False
    assert rig.errors == ["RuntimeError: model step failed"]
    assert rig.prepare_ahead() is False and len(rig.errors) == 1  # tried once, not again
    monkeypatch.undo()
    assert rig.handle_message(_frame(cia402.SYNC_COB_ID)) is None  # the SYNC computes it


def test_a_preparation_that_raises_after_the_model_step_leaves_the_model_as_it_was(
        monkeypatch) -> None:
    """The SYNC computes the answer again, so a preparation that fails after the model's step
    must take that step back: else the handle would move two periods for one SYNC."""
    rig, _ = _enabled_rig(_config())
    twin, _ = _enabled_rig(_config())
    for each in (rig, twin):
        each.handle_message(_frame(OPERATOR_DISPLAY_ID, encode_operator_display(
            np.array([1.5, -0.5])), extended=True))
    before = [getattr(holder, name).copy() for holder, name in rig._state_arrays]

    def broken(*args: object, **kwargs: object) -> None:
        raise RuntimeError("sensor encoding failed")

    monkeypatch.setattr(rig.codec, "to_counts", broken)
    assert rig.prepare_ahead() is False
    assert rig.errors == ["RuntimeError: sensor encoding failed"]
    for (holder, name), saved in zip(rig._state_arrays, before, strict=True):
        np.testing.assert_array_equal(getattr(holder, name), saved, err_msg=name)
    monkeypatch.undo()
    assert rig.handle_message(_frame(cia402.SYNC_COB_ID)) is None
    assert twin.handle_message(_frame(cia402.SYNC_COB_ID)) is None
    assert rig.sync_count == twin.sync_count
    np.testing.assert_array_equal(rig.last_sample.handle_position_m,
                                  twin.last_sample.handle_position_m)
    for (holder, name), (twin_holder, _) in zip(rig._state_arrays, twin._state_arrays,
                                                strict=True):
        np.testing.assert_array_equal(getattr(holder, name), getattr(twin_holder, name),
                                      err_msg=name)


# --- the sim backend against the emulator process ------------------------------------------


def test_the_sim_backend_configures_enables_and_follows_commands() -> None:
    config = _config(master__sim__initial_position_m=[0.012, -0.034])
    hardware = create_hardware("sim", config)
    assert isinstance(hardware, EmulatedRigHardware)
    assert hardware.lifecycle_state is LifecycleState.UNCONFIGURED
    try:
        hardware.configure()
        assert hardware.lifecycle_state is LifecycleState.INACTIVE
        process = hardware.process
        assert process is not None and process.poll() is None
        # its wake-ups never preempt the loops: SCHED_BATCH (no loop CPUs configured)
        assert os.sched_getscheduler(process.pid) == os.SCHED_BATCH
        assert hardware.emulator_cpus is None and hardware.emulator_cpu_warning is None
        # a process group of its own (a terminal's Ctrl-C reaches only the master), in the
        # master's session: with autogroup, a session of its own was starved on a busy machine
        assert os.getpgid(process.pid) == process.pid != os.getpgid(0)
        assert os.getsid(process.pid) == os.getsid(0)
        directory = Path(hardware.bus_options["channel"])
        assert hardware.bus_options["interface"] == "unix_datagram" and directory.is_dir()
        reading = hardware.read()
        assert reading.ok, reading.faults
        np.testing.assert_allclose(reading.position_m, [0.012, -0.034], atol=5e-7)
        hardware.activate()
        assert hardware.lifecycle_state is LifecycleState.ACTIVE
        assert hardware.driver.drive_states == (DriveState.OPERATION_ENABLED,) * 2
        target = np.array([0.012 + 1e-4, -0.034 - 2e-4])
        for _ in range(400):
            hardware.write(target)
            reading = hardware.read()
            assert reading.ok, reading.faults
        np.testing.assert_allclose(reading.position_m, target, atol=1e-6)
        hardware.deactivate()
        assert hardware.driver.drive_states == (DriveState.READY_TO_SWITCH_ON,) * 2
        assert hardware.driver.late_frames == 0
    finally:
        hardware.cleanup()
    assert hardware.lifecycle_state is LifecycleState.UNCONFIGURED
    assert _reaped(process) and process.returncode == 0  # SIGTERM: a clean exit
    assert not directory.exists()
    assert "answered as prepared" in hardware.emulator_output
    hardware.cleanup()  # a second cleanup is harmless


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="CPU affinity is Linux's")
def test_the_emulator_runs_on_the_masters_loop_cpus_under_normal_scheduling() -> None:
    """With [runner] loop_cpus the emulated drives share the master's loop CPU (they answer
    the SYNC while the loop sleeps) under normal scheduling; the summary says where."""
    from haptic.master.program import emulator_placement

    cpu = max(os.sched_getaffinity(0))
    hardware = create_hardware("sim", _config(runner__loop_cpus=str(cpu)))
    try:
        hardware.configure()
        process = hardware.process
        assert process is not None and process.poll() is None
        assert os.sched_getaffinity(process.pid) == {cpu}
        assert os.sched_getscheduler(process.pid) == os.SCHED_OTHER
        assert hardware.emulator_cpus == (cpu,) and hardware.emulator_cpu_warning is None
        assert hardware.read().ok
        assert emulator_placement(hardware) == {"rig_emulator_cpus": [cpu],
                                                "rig_emulator_cpu_warning": None}
    finally:
        hardware.cleanup()
    assert _reaped(process)


def test_beside_a_fifo_loop_the_emulator_runs_one_priority_above_it() -> None:
    """A master loop in SCHED_FIFO on its CPUs would starve emulated drives of normal
    scheduling there (they answer while it waits, and it spins before each tick): they run in
    SCHED_FIFO one above it. Elsewhere: normal beside a normal loop, batch off its CPUs."""
    from haptic.master.simulated_rig.rig_emulator import emulator_scheduling

    assert emulator_scheduling({"loop_cpus": "1", "realtime_priority": 40}) == [
        "--scheduling", "fifo", "--rt-priority", "41"]
    assert emulator_scheduling({"loop_cpus": "1", "realtime_priority": 0}) == [
        "--scheduling", "normal"]
    assert emulator_scheduling({"loop_cpus": "1", "realtime_priority": 99}) == [
        "--scheduling", "normal"]  # nothing above 99
    assert emulator_scheduling({"loop_cpus": "", "realtime_priority": 40}) == [
        "--scheduling", "batch"]
    cpu = max(os.sched_getaffinity(0))
    hardware = create_hardware("sim", _config(runner__loop_cpus=str(cpu),
                                              runner__realtime_priority=40))
    try:
        hardware.configure()
        process = hardware.process
        assert process is not None
        assert hardware.read().ok
        policy = os.sched_getscheduler(process.pid)
        if policy == os.SCHED_FIFO:
            assert os.sched_getparam(process.pid).sched_priority == 41
        else:  # a host that refuses SCHED_FIFO (it warns): normal scheduling, serving anyway
            assert policy == os.SCHED_OTHER
    finally:
        hardware.cleanup()
    assert _reaped(process)


def test_a_refused_placement_is_a_warning_and_the_emulator_runs_anywhere(
        monkeypatch, capsys) -> None:
    from haptic.master.program import emulator_placement

    def refuse(_pid: int, _cpus: object) -> None:
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "sched_setaffinity", refuse)
    hardware = create_hardware("sim", _config(runner__loop_cpus="0"))
    try:
        hardware.configure()
        assert hardware.emulator_cpus is None
        assert "were refused" in hardware.emulator_cpu_warning
        assert hardware.read().ok  # it serves all the same
        assert emulator_placement(hardware)["rig_emulator_cpus"] is None
        assert "haptic-master: the emulator's CPUs 0 were refused" in capsys.readouterr().err
    finally:
        hardware.cleanup()
    assert emulator_placement(object()) == {}  # no emulator process: nothing to say


def test_the_sim_backend_sends_its_targets_in_the_next_syncs_datagram() -> None:
    """The master's write (RPDOs and the operator display frame) waits for the next SYNC and
    goes with it in one datagram: one wake-up of the emulator a cycle, none in the tick."""
    import socket

    from haptic.master.hardware.unix_can import _HEADER

    config = _config()
    nodes = master_settings(config).can.node_ids
    hardware = create_hardware("sim", config)
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    try:
        hardware.configure()
        hardware.activate()
        listener.bind(str(Path(hardware.bus_options["channel"]) / "listener.sock"))
        listener.settimeout(1.0)
        time.sleep(1.1)  # the members rescan a directory whose clock has not moved (RESCAN_S)
        def datagrams(wait_s: float) -> list[list[int]]:
            """The frame ids of each datagram received within ``wait_s``."""
            got, deadline = [], time.monotonic() + wait_s
            while (left := deadline - time.monotonic()) > 0.0:
                listener.settimeout(left)
                try:
                    datagram = listener.recv(4096)
                except TimeoutError:
                    break
                ids, offset = [], 0
                while offset < len(datagram):
                    frame_id, _, length = _HEADER.unpack_from(datagram, offset)
                    ids.append(frame_id)
                    offset += _HEADER.size + length
                got.append(ids)
            return got

        rpdos = [0x200 + nodes[0], 0x200 + nodes[1]]
        hardware.read()
        datagrams(0.05)  # what came before the write (the queue holds only 10 datagrams)
        hardware.present_tool_force(np.array([0.5, 0.0]))
        hardware.write(np.array([0.0, 0.0]))
        held = datagrams(0.1)  # the emulator's heartbeats may come; the write may not
        assert not any(set(ids) & {*rpdos, OPERATOR_DISPLAY_ID} for ids in held), held
        hardware.read()
        with_sync = [ids for ids in datagrams(0.3) if cia402.SYNC_COB_ID in ids]
        assert len(with_sync) == 1, with_sync
        ids = with_sync[0]
        assert ids[:2] == rpdos and ids[-1] == cia402.SYNC_COB_ID
        assert OPERATOR_DISPLAY_ID in ids
    finally:
        listener.close()
        hardware.cleanup()


def test_the_emulated_operator_feels_the_presented_tool_force() -> None:
    """A regulating operator (target 2 N) holding the handle still (drives not enabled), so
    the sensor reads its intent force: steady while the displayed tool force is at the target,
    growing once the tool force drops 1.5 N below it (kp 0.5 at once, ki 4 over time)."""
    config = _config("regulate:fx=2,fy=0,kp=0.5,ki=4,lag=0.02,max=10")
    with create_hardware("sim", config) as hardware:
        hardware.configure()
        idle = hardware.read().force_N  # the operator waits for the ready lamp
        hardware.present_forces_enabled(True)
        forces = []
        for tool_force in [2.0] * 300 + [0.5] * 200:
            hardware.present_tool_force(np.array([tool_force, 0.0]))
            reading = hardware.read()
            assert reading.ok, reading.faults
            forces.append(reading.force_N)
    forces = np.array(forces)
    assert abs(idle[0]) < 0.05
    steady = forces[299, 0]
    assert abs(forces[250, 0] - steady) < 0.02 and forces[299, 1] == 0.0
    assert forces[-1, 0] > steady + 1.0  # felt below the target: pushes harder


def test_the_emulator_process_gives_the_in_process_rigs_trajectory() -> None:
    """The same devices, the same driver: the run over the emulator process (with sensor
    noise) is the run over the in-process rig, sample for sample."""
    config = _config("constant:fx=0.6,fy=-0.4,onset=0.05,rise=0.05",
                     master__sim__force_noise_std_N=0.05, master__sim__seed=11)
    traces = {}
    for rig in ("sim", "sim-inproc"):
        with create_hardware(rig, config) as hardware:
            summary = run_master(hardware, _node(config), 400, pace=False, record=True)
        assert not summary.hardware_faults
        traces[rig] = summary.trace
    np.testing.assert_array_equal(traces["sim"].handle_position_m,
                                  traces["sim-inproc"].handle_position_m)
    np.testing.assert_array_equal(traces["sim"].handle_force_N,
                                  traces["sim-inproc"].handle_force_N)
    assert abs(traces["sim"].handle_position_m[-1, 0]) > 1e-4


def test_runs_on_udp_multicast_get_private_ports_and_never_hear_each_other() -> None:
    base = _config(master__sim__emulator__interface="udp_multicast",
                   master__sim__emulator__channel="239.74.163.2")
    starts = {"a": [0.01, 0.02], "b": [-0.03, 0.04]}
    hardware = {name: create_hardware("sim", override(base, "master.sim.initial_position_m",
                                                      start))
                for name, start in starts.items()}
    try:
        for item in hardware.values():
            item.configure()
        assert hardware["a"].bus_options["port"] != hardware["b"].bus_options["port"]
        for item in hardware.values():
            item.activate()
        for _ in range(50):
            readings = {name: item.read() for name, item in hardware.items()}
            for name, reading in readings.items():
                assert reading.ok, reading.faults
                np.testing.assert_allclose(reading.position_m, starts[name], atol=5e-7)
        # udp_multicast hands the driver its own frames back: they are not late frames
        assert all(item.driver.late_frames == 0 for item in hardware.values())
    finally:
        for item in hardware.values():
            item.cleanup()
    assert all(_reaped(item.process) for item in hardware.values())


def test_a_start_timeout_is_a_hardware_error_and_the_child_is_reaped() -> None:
    hardware = create_hardware("sim", _config(master__sim__emulator__start_timeout_s=1e-3))
    with pytest.raises(HardwareError, match="not ready within"):
        hardware.configure()
    assert hardware.lifecycle_state is LifecycleState.UNCONFIGURED
    assert _reaped(hardware.process)
    assert not Path(hardware.bus_options["channel"]).exists()


def test_an_emulator_that_cannot_open_its_bus_fails_configure_with_its_message() -> None:
    # an interface python-can has, on a channel no host has (an unknown interface is a
    # configuration error before any process starts: tests/common/test_config.py)
    config = _config(master__sim__emulator__interface="socketcan",
                     master__sim__emulator__channel="no-such-can9")
    hardware = create_hardware("sim", config)
    with pytest.raises(HardwareError, match="ended .exit status 1.*cannot open the CAN bus"):
        hardware.configure()
    assert _reaped(hardware.process) and hardware.process.returncode == 1


def test_a_driver_that_fails_to_configure_leaves_no_emulator(monkeypatch) -> None:
    def refuse(self: CanHandleDriver) -> None:
        raise HardwareError("x drive write Modes of operation: no SDO reply from node 1")

    monkeypatch.setattr(CanHandleDriver, "configure", refuse)
    hardware = create_hardware("sim", _config())
    with pytest.raises(HardwareError, match="no SDO reply"):
        hardware.configure()
    assert hardware.lifecycle_state is LifecycleState.UNCONFIGURED
    assert _reaped(hardware.process) and hardware.process.returncode == 0
    with pytest.raises(HardwareError, match="configured"):
        hardware.read()
    hardware.write(np.zeros(2))  # unconfigured: ignored
    hardware.cleanup()


def test_the_can_backend_sends_no_operator_display_frame(tmp_path) -> None:
    """Real hardware keeps ignoring the presented tool force: nothing goes on the bus."""
    config = _config(master__can__interface="unix_datagram",
                     master__can__channel=str(tmp_path))
    listener = can.Bus(interface="unix_datagram", channel=str(tmp_path))
    try:
        hardware = create_hardware("can", config)
        assert type(hardware) is CanHandleDriver
        hardware.present_tool_force(np.array([1.0, 2.0]))
        assert listener.recv(0.05) is None
    finally:
        listener.shutdown()


# --- haptic-rig-sim ---------------------------------------------------------------------


@pytest.mark.parametrize(("argv", "named"), [
    (["--operator", "wiggle"], "--operator (master.sim.operator)"),
    (["--can-port", "0"], "--can-port"),
    (["--duration", "-1"], "--duration"),
    (["--can-interface", "udp_multicast", "--can-channel", "10.0.0.1"],
     "--can-channel (master.sim.emulator.channel)"),
    (["--can-interface", "virtual"], "--can-interface (master.sim.emulator.interface)"),
    (["--parent-pid", "0"], "--parent-pid"),
    (["--scheduling", "fifo"], "--rt-priority"),
    (["--scheduling", "fifo", "--rt-priority", "100"], "--rt-priority"),
    (["--rt-priority", "41"], "--rt-priority"),
    (["--config", "/no/such/file.toml"], "cannot read config file"),
])
def test_bad_options_exit_2_with_one_line_naming_them(argv, named, capsys) -> None:
    with pytest.raises(SystemExit) as caught:
        rig_sim_main(argv)
    assert caught.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and named in err[0], err


def test_a_bad_config_file_exits_2_naming_the_key(tmp_path, capsys) -> None:
    path = tmp_path / "bad.toml"
    path.write_text("[master.sim.emulator]\ninterface = \"unix_datagram\"\nchannel = \"\"\n"
                    "port = 70000\nstart_timeout_s = 1.0\n")
    with pytest.raises(SystemExit) as caught:
        rig_sim_main(["--config", str(path)])
    assert caught.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "master.sim.emulator.port" in err[0]


def _start_emulator(programs: Programs, *argv: str) -> tuple[Program, str]:
    """An emulator and its ready line (fails when it does not say it is ready in time)."""
    process = programs.start(python_module("haptic.master.simulated_rig.cli", *argv))
    ready = process.wait_for(rf"^{re.escape(READY_PREFIX)}.*$", timeout_s=WAIT_S)
    return process, ready.group(0)


@pytest.mark.parametrize("number", [signal.SIGTERM, signal.SIGINT])
def test_the_emulator_says_when_it_is_ready_and_ends_cleanly_on_a_signal(tmp_path,
                                                                          number) -> None:
    with Programs() as programs:
        process, ready = _start_emulator(programs, "--can-channel", str(tmp_path / "bus"))
        assert ready.startswith(READY_PREFIX) and str(tmp_path / "bus") in ready
        process.send_signal(number)
        assert process.wait(timeout_s=WAIT_S) == 0
        assert "stopped after 0 SYNCs" in process.output()
    assert list((tmp_path / "bus").iterdir()) == []  # it left the bus


def test_the_emulator_ends_after_its_duration_and_when_its_parent_is_gone(tmp_path) -> None:
    with Programs() as programs:
        process, ready = _start_emulator(programs, "--can-channel", str(tmp_path),
                                         "--duration", "0.3")
        assert ready.startswith(READY_PREFIX)
        assert process.wait(timeout_s=WAIT_S) == 0
    # A parent that starts an emulator watching it, prints its PID and exits (SIGKILL-like:
    # no cleanup): the emulator notices and ends by itself.
    script = ("import os, subprocess, sys\n"
              "child = subprocess.Popen([sys.executable, '-m', 'haptic.master.simulated_rig.cli',"
              f" '--can-channel', {str(tmp_path / 'orphan')!r}, '--parent-pid',"
              " str(os.getpid())], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,"
              " text=True)\n"
              "print(child.stdout.readline().strip(), flush=True)\n"
              "print(child.pid, flush=True)\n"
              "os._exit(0)\n")
    parent = run_to_end([sys.executable, "-c", script], timeout_s=WAIT_S)
    ready_line, pid_line = parent.stdout.strip().splitlines()
    assert ready_line.startswith(READY_PREFIX)
    orphan = int(pid_line)
    deadline = time.monotonic() + WAIT_S
    while _alive(orphan):
        assert time.monotonic() < deadline, "the orphaned emulator kept running"
        time.sleep(0.05)
    assert list((tmp_path / "orphan").iterdir()) == []


def _alive(pid: int) -> bool:
    """The process runs (a zombie waiting for its new parent's reaping does not)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, IndexError):
        return False
    return state not in ("Z", "X")


def test_haptic_master_drives_an_emulator_started_by_hand(tmp_path, capsys) -> None:
    """``haptic-rig-sim`` by hand, then the master's ``can`` backend on the same bus."""
    from haptic.master.cli import main as master_main

    bus = tmp_path / "bus"
    config = override(_config("constant:fx=1,fy=0,onset=0.02"), "master.can.pdo_timeout_s",
                      0.5)  # a shared machine: the real-rig 2 ms timeout is too tight here
    path = tmp_path / "rig.toml"
    path.write_text(to_toml(config))
    with Programs() as programs:
        process, ready = _start_emulator(programs, "--config", str(path), "--can-channel",
                                         str(bus))
        assert ready.startswith(READY_PREFIX)
        status = master_main(["--config", str(path), "--rig", "can", "--can-interface",
                              "unix_datagram", "--can-channel", str(bus), "--no-link",
                              "--no-pace", "--duration", "0.1", "--json"])
        printed = capsys.readouterr()
        assert status == 0, printed.err  # a hardware error prints one line there, no JSON
        result = json.loads(printed.out)
        assert result["rig"] == "can" and result["cycles"] == 185
        assert result["final_position_m"][0] > 0.0 and not result["hardware_faults"]
        assert process.stop(signal.SIGTERM, grace_s=WAIT_S) == 0


def _serve_for(rig: SimulatedCanRig, seconds: float) -> None:
    stop_at = time.monotonic() + seconds
    rig.serve(lambda: time.monotonic() > stop_at, 0.01)


def _emcy_ids(bus: can.BusABC) -> list[int]:
    ids = []
    while (message := bus.recv(0.0)) is not None:
        if cia402.EMCY_BASE < message.arbitration_id <= cia402.EMCY_BASE + 0x7F:
            ids.append(message.arbitration_id)
    return ids


def test_a_heartbeat_that_came_while_the_emulator_was_not_scheduled_counts(tmp_path) -> None:
    """A busy machine: the master's heartbeat arrives on time but waits in the emulator's
    queue while the emulator is descheduled past the consumer time; when it runs again it
    takes the frames already there before it judges the consumer, so no EMCY 0x8130 (the
    heartbeat was not lost). A heartbeat that really stops still trips it."""
    rig = SimulatedCanRig.from_config(load_config(), "unused")
    master = can.Bus(interface="unix_datagram", channel=str(tmp_path))
    emulator = can.Bus(interface="unix_datagram", channel=str(tmp_path))
    try:
        rig.attach(emulator)
        for device in rig.devices:  # consume the master's heartbeat (node 127), 300 ms
            device.node.sdo[0x1016][1].raw = (127 << 16) | 300
            device.refresh()
        heartbeat = can.Message(arbitration_id=0x77F, data=b"\x05", is_extended_id=False)
        master.send(heartbeat)
        _serve_for(rig, 0.05)  # the consumers start
        assert _emcy_ids(master) == []  # (the master reads what the drives sent)
        time.sleep(0.2)
        master.send(heartbeat)  # on time; the emulator is not running
        time.sleep(0.2)  # it runs again 0.4 s after the first heartbeat
        _serve_for(rig, 0.05)
        assert _emcy_ids(master) == []
        time.sleep(0.4)  # now the master is silent past the consumer time
        _serve_for(rig, 0.05)
        assert sorted(_emcy_ids(master)) == [cia402.EMCY_BASE + device.node_id
                                             for device in rig.devices]
    finally:
        master.shutdown()
        emulator.shutdown()
