"""The CAN driver against the simulated rig on python-can's virtual bus."""

from __future__ import annotations

import uuid

import can
import control
import numpy as np
import pytest
import scipy.signal

from haptic.common.config import load_config, override
from haptic.common.model.teleop import model_from_config
from haptic.master.hardware.can_driver import CanHandleDriver
from haptic.master.hardware.cia402 import DriveState
from haptic.master.hardware.interface import (
    HandleHardware,
    HardwareError,
    LifecycleState,
    create_hardware,
    hardware_names,
)
from haptic.master.node import MasterNode
from haptic.master.settings import master_settings
from haptic.master.simulated_rig.can_devices import (
    NMT_OPERATIONAL_STATE,
    SimulatedCanRig,
    SimulatedRigHardware,
)
from haptic.master.simulated_rig.rig_block import RigModel
from haptic.master.standalone import run_master


def _config(operator: str = "constant:fx=0,fy=0", **overrides):
    config = load_config()
    config = override(config, "master.sim.operator", operator)
    config = override(config, "master.sim.channel", f"test-{uuid.uuid4().hex}")
    # The heartbeats both ways are wall-clock supervision (tested in
    # test_can_commissioning.py); these runs step unpaced, and a loaded machine that stalls
    # the emulation threads for 0.2 s would trip the default 0.3 s consumer time (a drive
    # tripped by a lost heartbeat at step 172 of the NaN test once, in CI).
    config = override(config, "master.can.heartbeat_timeout_s", 5.0)
    for key, value in overrides.items():
        config = override(config, key.replace("__", "."), value)
    return config


def _node(config) -> MasterNode:
    return MasterNode.from_model(model_from_config(config), master_settings(config).safety)


def test_backends_are_registered_by_name() -> None:
    assert {"can", "sim"} <= set(hardware_names())
    with pytest.raises(KeyError, match="no handle hardware named"):
        create_hardware("simulated", load_config())


def test_configure_sets_csp_mode_over_sdo_and_the_enable_sequence_runs() -> None:
    config = _config(master__sim__initial_position_m=[0.012, -0.034])
    with create_hardware("sim-inproc", config) as hardware:
        assert isinstance(hardware, SimulatedRigHardware)
        assert hardware.lifecycle_state is LifecycleState.UNCONFIGURED
        hardware.configure()
        assert hardware.lifecycle_state is LifecycleState.INACTIVE
        rig, driver = hardware.rig, hardware.driver
        assert [d.mode for d in rig.drives] == [8, 8]
        assert [d.nmt_state for d in rig.drives] == [NMT_OPERATIONAL_STATE] * 2
        assert driver.drive_states == (DriveState.SWITCH_ON_DISABLED,) * 2
        reading = hardware.read()
        np.testing.assert_allclose(reading.position_m, [0.012, -0.034], atol=5e-7)
        hardware.write(np.array([0.05, 0.05]))  # inactive: no command goes out
        cycles_before = reading.cycle
        hardware.activate()
        assert hardware.lifecycle_state is LifecycleState.ACTIVE
        assert driver.drive_states == (DriveState.OPERATION_ENABLED,) * 2
        assert [d.state for d in rig.drives] == [DriveState.OPERATION_ENABLED] * 2
        # shutdown, switch on, enable operation: one SYNC each, plus the first read.
        assert driver.last_reading.cycle - cycles_before == 4
        for _ in range(50):  # enabled, holding: no jump
            reading = hardware.read()
            assert reading.ok, reading.faults
        np.testing.assert_allclose(reading.position_m, [0.012, -0.034], atol=5e-7)
        hardware.deactivate()
        assert driver.drive_states == (DriveState.READY_TO_SWITCH_ON,) * 2
        assert hardware.read().ok
    assert hardware.lifecycle_state is LifecycleState.UNCONFIGURED


def test_enable_sequence_resets_a_faulted_drive() -> None:
    with create_hardware("sim-inproc", _config()) as hardware:
        hardware.configure()
        hardware.rig.inject_drive_fault(0, 0x7500)
        reading = hardware.read()
        assert any("EMCY error code 0x7500" in f for f in reading.faults)
        assert any("x drive in fault" in f for f in reading.faults)
        hardware.activate()
        assert hardware.driver.drive_states == (DriveState.OPERATION_ENABLED,) * 2


def test_activate_reports_a_drive_that_will_not_enable() -> None:
    config = _config(master__can__enable_timeout_cycles=6)
    with create_hardware("sim-inproc", config) as hardware:
        hardware.configure()
        hardware.rig.drives[1].mode = 0  # the y drive left CSP mode: it ignores controlwords
        with pytest.raises(HardwareError, match="did not reach operation enabled"):
            hardware.activate()
        assert hardware.lifecycle_state is LifecycleState.INACTIVE


def test_configure_without_an_answering_drive_is_a_hardware_error() -> None:
    config = _config(master__can__enable_timeout_cycles=2, master__sim__pdo_timeout_s=0.02)
    settings = master_settings(config)
    driver = CanHandleDriver(settings.can, {"interface": "virtual",
                                            "channel": settings.sim.channel}, 0.02,
                             config["model"]["sample_period_s"])
    with pytest.raises(HardwareError, match="no SDO reply"):
        driver.configure()
    assert driver.lifecycle_state is LifecycleState.UNCONFIGURED


def test_the_can_backend_runs_unchanged_against_the_simulated_devices() -> None:
    config = _config(master__can__interface="virtual", master__can__pdo_timeout_s=0.5)
    config = override(config, "master.can.channel", config["master"]["sim"]["channel"])
    settings = master_settings(config)
    model = model_from_config(config)
    rig = SimulatedCanRig(RigModel.from_model(model, settings.sim.operator), settings.can,
                          settings.can.channel, (0.0, 0.0), np.random.default_rng(0))
    rig.start()
    try:
        with create_hardware("can", config) as hardware:
            assert type(hardware) is CanHandleDriver
            hardware.configure()
            hardware.activate()
            hardware.write(np.array([1e-4, -2e-4]))
            for _ in range(400):
                reading = hardware.read()
                hardware.write(np.array([1e-4, -2e-4]))
            assert reading.ok
            np.testing.assert_allclose(reading.position_m, [1e-4, -2e-4], atol=1e-6)
    finally:
        rig.stop()
    assert not rig.errors


def test_missing_pdo_is_reported_and_the_master_goes_safe() -> None:
    config = _config("constant:fx=1,fy=0,onset=0.02", master__sim__pdo_timeout_s=0.25)
    hardware = create_hardware("sim-inproc", config)

    def drop(cycle: int) -> None:
        if cycle == 300:
            hardware.rig.drop_tpdo(1, 1)

    with hardware:
        summary = run_master(hardware, _node(config), 400, pace=False, record=True,
                             on_cycle=drop)
    assert summary.safe_state
    assert any("missing TPDO1 from the y drive (node 2)" in f for f in summary.hardware_faults)
    trip = [e for e in summary.events if e.kind == "trip"][0]
    assert "missing TPDO1" in trip.reason and trip.step == 301, (trip, summary.hardware_faults)
    commands = summary.trace.handle_command_m
    assert np.all(np.isfinite(commands))
    np.testing.assert_array_equal(commands[301:], np.repeat(commands[301:302], 99, axis=0))
    assert hardware.driver.late_frames == 0  # the dropped frame was never sent


def test_drive_fault_during_a_run_is_reported_and_the_master_goes_safe() -> None:
    config = _config("constant:fx=1,fy=0,onset=0.02")
    hardware = create_hardware("sim-inproc", config)

    def fault(cycle: int) -> None:
        if cycle == 200:
            hardware.rig.inject_drive_fault(1)

    with hardware:
        summary = run_master(hardware, _node(config), 300, pace=False, on_cycle=fault)
    assert summary.safe_state
    assert any("EMCY error code 0x2310" in f for f in summary.hardware_faults)
    assert any("y drive in fault" in f for f in summary.hardware_faults)


def test_a_nan_force_from_the_sensor_never_reaches_a_drive() -> None:
    config = _config("constant:fx=2,fy=-1,onset=0.02,rise=0.02")
    hardware = create_hardware("sim-inproc", config)
    received_targets: list[list[int]] = []

    def watch(cycle: int) -> None:
        if cycle == 250:
            hardware.rig.set_sensor_status(2, count=3)  # "invalid": the driver gives NaN
        received_targets.append([d.target_counts for d in hardware.rig.drives])

    with hardware:
        summary = run_master(hardware, _node(config), 650, pace=False, record=True,
                             on_cycle=watch)
    forces = summary.trace.handle_force_N
    assert np.isnan(forces[251]).all()  # the NaN did arrive at the node ...
    assert summary.safe_state
    trips = [e for e in summary.events if e.kind == "trip"]
    assert trips[0].step == 251
    commands = summary.trace.handle_command_m
    assert np.all(np.isfinite(commands))  # ... and never left it
    hold = commands[251]
    np.testing.assert_array_equal(commands[251:], np.repeat(hold[None], 399, axis=0))
    settings = master_settings(config).can
    final_targets = np.array(received_targets[-1])
    np.testing.assert_array_equal(final_targets, settings.counts_from_metres(hold))
    # The handle had been moving, and stopped where it was when the NaN came (the servo
    # settles on the held target in about 0.1 s, Gh's own transient).
    positions = summary.trace.handle_position_m
    assert abs(positions[250, 0] - positions[0, 0]) > 1e-3
    np.testing.assert_allclose(positions[-1], hold, atol=2e-5)
    assert np.ptp(positions[-100:], axis=0).max() < 2e-6


def test_driver_never_sends_a_non_finite_command() -> None:
    with create_hardware("sim-inproc", _config()) as hardware:
        hardware.configure()
        hardware.activate()
        before = [d.target_counts for d in hardware.rig.drives]
        hardware.write(np.array([np.nan, 0.001]))
        reading = hardware.read()
        assert "non-finite position command refused" in reading.faults
        after = [d.target_counts for d in hardware.rig.drives]
        assert after[0] == before[0]
        assert after[1] == master_settings(_config()).can.counts_from_metres(0.001)


def _ch1_prediction(model, trace, delay_samples: int) -> np.ndarray:
    """Continuous Gh Ch1 driven by the force the compensator saw (held over each period),
    delayed by ``delay_samples``, from the starting position."""
    ts = model.sample_period_s
    force = trace.force_scale[:, None] * trace.handle_force_N
    times = np.arange(len(force)) * ts
    prediction = np.empty_like(force)
    for index, axis in enumerate("xy"):
        open_loop = model.axis(axis).handle_actuator_gh * model.ch1
        system = scipy.signal.lti(open_loop.num[0][0], open_loop.den[0][0])
        _, response, _ = scipy.signal.lsim(system, force[:, index], times, interp=False)
        shifted = np.concatenate([np.zeros(delay_samples), response[:len(response) -
                                                                     delay_samples]])
        prediction[:, index] = trace.handle_position_m[0, index] + shifted
    return prediction


def test_the_handle_moves_as_ch1_predicts_for_a_constant_operator_force() -> None:
    """No slave (zero tool force), a constant operator force after the force ramp.

    1. Open loop: the handle follows continuous Gh Ch1 applied to the force the node
       measured, one sample late (the drive's CSP latency). What is left is encoder
       rounding (+-0.5 count = 0.25 um) and the Tustin-vs-continuous Ch1 difference, which
       is O((w Ts)^2) on signals far below 1/Ts: we allow 2 counts (1 um). A wrong timing
       contract (no delay, or two samples) is off by Ts x speed, over 10 um here.
    2. Closed loop with the operator's arm: yh = Gh Ch1 / (1 + Gh Ch1 Th) uh, the paper's
       continuous model. The sampled loop differs by O(Ts): the sensor samples the arm's
       inertial force 0.25 yh'' right after each SYNC, where the acceleration jumps with the
       new command (Gh has relative degree 2), and Ch1's integrator sums that bias. It is
       1.6 % of the travel at Ts = 0.54 ms and shrinks in proportion to Ts
       (test_rig_block checks the convergence); we allow 3 %.
    """
    config = _config("constant:fx=0.6,fy=-0.4,onset=0.25,rise=0.05")
    model = model_from_config(config)
    settings = master_settings(config)
    ts = model.sample_period_s
    with create_hardware("sim-inproc", config) as hardware:
        summary = run_master(hardware, _node(config), round(1.5 / ts), pace=False,
                             record=True)
    assert not summary.safe_state and not summary.hardware_faults
    trace = summary.trace
    positions = trace.handle_position_m
    counts_m = settings.can.metres_per_count
    error = np.abs(positions - _ch1_prediction(model, trace, 1))
    assert error.max() <= 2 * counts_m
    for wrong in (0, 2):
        assert np.abs(positions - _ch1_prediction(model, trace, wrong)).max() > 10e-6
    travel = np.abs(positions[-1] - positions[0])
    assert travel[0] > 0.02 and travel[1] > 0.01
    times = np.arange(len(positions)) * ts
    intent = np.array([0.6, -0.4]) * np.clip((times[:, None] - 0.25) / 0.05, 0.0, 1.0)
    assert trace.force_scale[round(0.25 / ts)] == 1.0  # the ramp was over before the push
    for index, axis in enumerate("xy"):
        parts = model.axis(axis)
        loop = parts.handle_actuator_gh * model.ch1
        closed = control.feedback(loop, control.tf(parts.operator_impedance_th_N_per_m, [1.0]))
        _, predicted = control.forced_response(closed, times, intent[:, index])
        deviation = np.abs(positions[:, index] - positions[0, index] - predicted)
        assert deviation.max() <= 0.03 * travel[index]


def test_runs_are_deterministic_with_seeded_sensor_noise() -> None:
    def run() -> np.ndarray:
        config = _config("constant:fx=0.5,fy=0.2,onset=0.02", master__sim__force_noise_std_N=0.05,
                         master__sim__seed=7)
        with create_hardware("sim-inproc", config) as hardware:
            return run_master(hardware, _node(config), 300, pace=False,
                              record=True).trace.handle_position_m

    np.testing.assert_array_equal(run(), run())


def test_regulating_operator_feels_the_tool_force_through_the_rig() -> None:
    config = _config("regulate:fx=2,fy=0,kp=0.5,ki=4,lag=0.02,max=10")
    with create_hardware("sim-inproc", config) as hardware:
        assert isinstance(hardware, HandleHardware)
        hardware.configure()
        hardware.activate()
        for _ in range(20):  # the operator waits for the master's ready lamp
            hardware.read()
        assert hardware.rig.last_sample.operator_intent_force_N[0, 0] == 0.0
        hardware.present_forces_enabled(True)
        hardware.present_tool_force(np.array([1.5, 0.0]))
        hardware.read()
        np.testing.assert_array_equal(hardware.rig.tool_force_N, [[1.5, 0.0]])
        for _ in range(200):
            hardware.read()
        # Felt 1.5 N below the 2 N target: the operator pushes above the target.
        assert hardware.rig.last_sample.operator_intent_force_N[0, 0] > 2.0


def test_scalar_count_conversions_match_the_array_ones() -> None:
    settings = master_settings(_config()).can
    metres_per_count = settings.metres_per_count
    rng = np.random.default_rng(3)
    positions = np.concatenate([rng.uniform(-0.2, 0.2, 500),
                                (np.arange(-5, 5) + 0.5) * metres_per_count])  # ties
    for position in positions:
        assert settings.count_from_metres(float(position)) == int(
            settings.counts_from_metres(position))
    for count in rng.integers(-2**31, 2**31, 200):
        assert settings.metres_from_count(int(count)) == float(settings.metres_from_counts(count))


def _rpdo_listener(config: dict, nodes: tuple[int, int], sync: bool = False) -> can.BusABC:
    """A member of the in-process rig's virtual bus that hears the drives' RPDOs, the extra
    frame 0x1FFFF00F and, with ``sync``, the SYNC (not the heartbeats)."""
    filters = [{"can_id": 0x200 + node, "can_mask": 0x7FF, "extended": False} for node in nodes]
    if sync:
        filters.append({"can_id": 0x080, "can_mask": 0x7FF, "extended": False})
    filters.append({"can_id": 0x1FFFF00F, "can_mask": 0x1FFFFFFF, "extended": True})
    return can.Bus(interface="virtual", channel=config["master"]["sim"]["channel"],
                   can_filters=filters)


@pytest.fixture
def active_rig():
    """(config, the in-process rig's hardware, active, its driver, the drives' node ids)."""
    config = _config()
    with create_hardware("sim-inproc", config) as hardware:
        hardware.configure()
        hardware.activate()
        yield config, hardware, hardware.driver, master_settings(config).can.node_ids


def test_a_burst_sends_the_rpdos_and_the_extra_frames_after_them_in_order(active_rig) -> None:
    config, hardware, driver, nodes = active_rig
    listener = _rpdo_listener(config, nodes)  # the RPDOs and the extra frame
    try:
        with driver.burst():
            driver.write(np.array([0.001, -0.002]))
            with driver.burst():  # nested: goes out with the outer one
                driver.send_frame(0x1FFFF00F, b"\x01", extended=True)
            assert listener.recv(0.05) is None  # held until the burst ends
        ids = [listener.recv(1.0).arbitration_id for _ in range(3)]
    finally:
        listener.shutdown()
    assert ids == [0x200 + nodes[0], 0x200 + nodes[1], 0x1FFFF00F]
    reading = hardware.read()  # the drives took the burst's targets
    assert not reading.faults
    assert [d.target_counts for d in hardware.rig.drives] == [
        master_settings(config).can.count_from_metres(v) for v in (0.001, -0.002)]


def test_frames_held_until_the_sync_go_out_just_before_it_and_before_anything_later(
        active_rig) -> None:
    """until_sync(): the frames wait for the next SYNC and lead its burst; a frame sent in
    between (a quick stop) sends them first, so the later command still wins."""
    config, hardware, driver, nodes = active_rig
    listener = _rpdo_listener(config, nodes, sync=True)  # and the SYNC
    try:
        with driver.until_sync():
            driver.write(np.array([0.001, -0.002]))
            driver.send_frame(0x1FFFF00F, b"\x01", extended=True)
        assert listener.recv(0.05) is None  # held for the SYNC
        driver.sync()
        ids = [listener.recv(1.0).arbitration_id for _ in range(4)]
        assert ids == [0x200 + nodes[0], 0x200 + nodes[1], 0x1FFFF00F, 0x080]
        reading = hardware.read()  # the drives took the held targets at that SYNC
        assert not reading.faults
        assert [d.target_counts for d in hardware.rig.drives] == [
            master_settings(config).can.count_from_metres(v) for v in (0.001, -0.002)]
        # a frame sent on its own while targets wait for the SYNC goes out after them
        with driver.until_sync():
            driver.write(np.array([0.001, -0.002]))
        driver.send_frame(0x1FFFF00F, b"\x02", extended=True)
        assert [listener.recv(1.0).arbitration_id for _ in range(3)] == [
            0x200 + nodes[0], 0x200 + nodes[1], 0x1FFFF00F]
        # a quick stop sent while targets wait for the SYNC goes out after them
        with driver.until_sync():
            driver.write(np.array([0.002, -0.003]))
        driver.stop_motion("test")
        got = [listener.recv(1.0) for _ in range(4)]
        assert [m.arbitration_id for m in got] == [0x200 + nodes[0], 0x200 + nodes[1]] * 2
        controlwords = [int.from_bytes(bytes(m.data[:2]), "little") for m in got]
        assert controlwords[2:] == [0x0002, 0x0002]  # quick stop last
        assert controlwords[:2] != [0x0002, 0x0002]
        hardware.read()
        hardware.read()
        assert all(d.state is DriveState.QUICK_STOP_ACTIVE or
                   d.state is DriveState.SWITCH_ON_DISABLED for d in hardware.rig.drives)
    finally:
        listener.shutdown()


def test_a_prepared_answer_copies_the_drives() -> None:
    from haptic.master.hardware.drive_device import DriveRuntime

    drive = DriveRuntime(3, target_counts=5, last_tpdos=(b"\x01",))
    clone = drive.copy()
    assert clone == drive and clone is not drive
    clone.target_counts = 9
    assert drive.target_counts == 5


@pytest.mark.parametrize("command_m", [1e4, -1e4, 1e15, 1e300])
def test_a_command_beyond_the_drives_range_is_refused_never_sent(command_m: float) -> None:
    with create_hardware("sim-inproc", _config()) as hardware:
        hardware.configure()
        hardware.activate()
        before = [d.target_counts for d in hardware.rig.drives]
        hardware.write(np.array([command_m, 0.001]))  # never raises
        reading = hardware.read()
        assert "position command beyond the drives' int32 range" in reading.faults
        assert [d.target_counts for d in hardware.rig.drives] == before  # both held
