"""The slave node: tool plant, compensators, the clay and linear environments, safe stop."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import expm

from haptic.common.config import ConfigError, load_config, override
from haptic.common.config.scenario import load_scenario
from haptic.common.model.synthesis import synthesize
from haptic.common.model.teleop import evaluate_tf, model_from_config
from haptic.slave_sim.node import SlaveNode, slave_compensators
from haptic.slave_sim.tool import tool_plant


@pytest.fixture(scope="module")
def model():
    return model_from_config(load_config())


def transfer(block, input_index: int, output_index: int, z: complex) -> complex:
    """Frequency response of one path of a discrete block at ``z``."""
    n = block.n_states
    gain = block.C @ np.linalg.solve(z * np.eye(n) - block.A, block.B) + block.D
    return complex(gain[output_index, input_index])


def test_tool_plant_is_exact_for_a_held_force(model) -> None:
    plant = tool_plant(model)
    state = plant.initial_state(1)
    force_N, mass, damping = 2.5, 1.0, 100.0
    ts = model.sample_period_s
    for k in range(1, 400):
        plant.step(state, np.array([[force_N, -force_N]]))
        t = k * ts
        velocity = force_N / damping * (1 - np.exp(-damping * t / mass))
        position = force_N / damping * (t - mass / damping * (1 - np.exp(-damping * t / mass)))
        np.testing.assert_allclose(state[0], [position, velocity, -position, -velocity],
                                   rtol=1e-9, atol=1e-15)


def test_compensators_follow_the_synthesis(model) -> None:
    block = slave_compensators(model)
    assert block.input_names == ("fh_x", "fh_y", "ft_x", "ft_y")
    ts = model.sample_period_s
    for axis_index, axis in enumerate(synthesize(model)):
        for omega in (1.0, 10.0, 100.0):
            z = np.exp(1j * omega * ts)
            s = np.array([1j * omega])
            ch2 = evaluate_tf(axis.ch2, s)[0]
            ct2 = evaluate_tf(axis.ct2, s)[0]
            assert transfer(block, axis_index, axis_index, z) == pytest.approx(-ch2, rel=1e-3)
            assert transfer(block, 2 + axis_index, axis_index, z) == pytest.approx(ct2, rel=1e-3)
        other = 1 - axis_index
        assert transfer(block, other, axis_index, 1.0) == 0


def test_constant_handle_force_cuts_each_block_at_its_own_speed(model) -> None:
    """The paper's variable-rate experiment on the slave alone: with the handle force fh the
    tool follows yt = Gh Ch1 (fh - ft), so with ft = B v the speed settles at
    k fh / (10 + k B) in each block (Ch1 = k / (s^2 + 10 s), Gh(0) = 1). Checked where that
    loop is well damped (B <= 60); at B = 80 and 100 it rings near 66 rad/s (docs/clay.md)."""
    scenario = load_scenario("variable-rate").with_grid(512, 128)
    node = SlaveNode(model, scenario, clay_impl="warp", device="cpu")
    state = node.initial_state(1)
    handle_force = np.array([[3.0, 0.0]])
    xs, vs, fs = [], [], []
    for _ in range(int(4.0 / node.sample_period_s)):
        out = node.step(state, handle_force, np.zeros((1, 2)))
        xs.append(out.tool_position_m[0, 0])
        vs.append(out.tool_velocity_m_s[0])
        fs.append(out.tool_force_N[0])
        if xs[-1] > 0.17:
            break
    xs, vs, fs = np.array(xs), np.array(vs), np.array(fs)
    gain_k = model.ch1_gain_k
    speeds = []
    for start, damping in zip((0.08, 0.11, 0.14), (60, 40, 20), strict=True):
        steady = (xs > start + 0.012) & (xs < start + 0.03 - 0.008)
        speed = vs[steady, 0].mean()
        assert speed == pytest.approx(gain_k * 3.0 / (10 + gain_k * damping), rel=0.03)
        assert fs[steady, 0].mean() == pytest.approx(damping * speed, rel=0.05)
        assert abs(vs[steady, 1]).max() < 1e-12 and abs(fs[steady, 1]).max() < 1e-12
        speeds.append(speed)
    assert speeds == sorted(speeds)
    assert xs[-1] > 0.17  # the tool got through the whole staircase
    clay = state.environment
    assert abs(clay.conservation_error_m3()[0]) < 1e-5 * clay.removed_total_m3[0]


def test_linear_environment_is_tt_of_the_exact_tool_motion(model) -> None:
    scenario = load_scenario("constant-rate")
    node = SlaveNode(model, scenario, environment="linear")
    assert node.environment_kind == "linear"
    state = node.initial_state(1, start_position_m=np.array([0.01, -0.02]))
    mass, damping = 1.0, 100.0
    continuous_a = np.array([[0.0, 1.0], [0.0, -damping / mass]])
    x_axis = np.array([0.01, 0.0])
    y_axis = np.array([-0.02, 0.0])
    rng = np.random.default_rng(7)
    ts = node.sample_period_s
    for _ in range(300):
        out = node.step(state, rng.normal(0.0, 2.0, size=(1, 2)), np.zeros((1, 2)))
        for axis, exact in enumerate((x_axis, y_axis)):
            force = out.actuator_force_N[0, axis]
            augmented = np.zeros((3, 3))
            augmented[:2, :2] = continuous_a
            augmented[1, 2] = 1.0 / mass
            exact[:] = (expm(augmented * ts) @ np.array([*exact, force]))[:2]
            acceleration = (force - damping * exact[1]) / mass
            expected = 0.25 * acceleration + 2.0 * exact[1] + 6.0 * exact[0]
            assert out.tool_force_N[0, axis] == pytest.approx(expected, rel=1e-9, abs=1e-12)


def test_lanes_step_like_separate_nodes(model) -> None:
    scenario = load_scenario("arbitrary").with_grid(256, 128)
    node = SlaveNode(model, scenario, clay_impl="numpy")
    forces = np.array([[3.0, 0.5], [2.0, -1.0], [4.0, 0.0]])
    together = node.initial_state(3)
    apart = [node.initial_state(1) for _ in range(3)]
    for _ in range(1500):
        out = node.step(together, forces, np.zeros((3, 2)))
        for lane, state in enumerate(apart):
            single = node.step(state, forces[lane:lane + 1], np.zeros((1, 2)))
            np.testing.assert_allclose(out.tool_position_m[lane], single.tool_position_m[0],
                                       rtol=1e-12, atol=1e-15)
            np.testing.assert_allclose(out.tool_force_N[lane], single.tool_force_N[0],
                                       rtol=1e-9, atol=1e-12)
    assert together.environment.removed_total_m3.min() > 0


def test_safe_stop_holds_the_tool_and_sends_no_force(model) -> None:
    node = SlaveNode(model, load_scenario("constant-rate").with_grid(256, 64), device="cpu")
    state = node.initial_state(2)
    push = np.array([[3.0, 0.0], [3.0, 0.0]])
    for _ in range(600):
        node.step(state, push, np.zeros((2, 2)))
    assert state.tool_velocity_m_s()[:, 0].min() > 0.01
    node.safe_stop(state, np.array([True, False]))
    stopped_at = state.tool_position_m()[0].copy()
    assert not state.tool_velocity_m_s()[0].any() and not state.tool_force_N[0].any()
    other_at = state.tool_position_m()[1].copy()
    for _ in range(100):
        out = node.step(state, push, np.zeros((2, 2)))
        assert not out.actuator_force_N[0].any() and not out.tool_force_N[0].any()
        np.testing.assert_array_equal(out.tool_position_m[0], stopped_at)
    assert abs(out.tool_position_m[1, 0] - other_at[0]) > 1e-4  # the other lane runs on
    node.resume(state, np.array([True, False]))
    for _ in range(200):
        out = node.step(state, push, np.zeros((2, 2)))
    assert out.tool_position_m[0, 0] > stopped_at[0]


def test_node_from_config_and_its_errors(tmp_path) -> None:
    config = override(load_config(), "slave.environment", "linear")
    node = SlaveNode.from_config(config)
    assert node.environment_kind == "linear" and node.scenario.name == "constant-rate"
    massless = override(load_config(), "model.x.tool_mass_kg", 0.0)
    with pytest.raises(ConfigError) as error:
        SlaveNode.from_config(massless)
    assert error.value.key == "model.x.tool_mass_kg"


def test_tool_started_inside_the_clay_feels_no_spike(model) -> None:
    scenario = load_scenario("variable-rate").with_grid(512, 128)
    node = SlaveNode(model, scenario, device="cpu")
    state = node.initial_state(1, start_position_m=np.array([0.035, 0.0]))  # inside p100
    damping_max = 100.0
    proxy = np.array([0.035, 0.0])
    forces, speeds = [], []
    for _ in range(400):
        out = node.step(state, np.array([[3.0, 0.0]]), state.tool_position_m())
        force = np.linalg.norm(out.tool_force_N[0])
        moved = state.environment.proxy_position_m()[0]
        # the contact law: ft = c dp/dt with c <= B_max, at every step (dp of 1e-9 m at
        # positions of 0.035 m: 1e-6 relative is the rounding of the difference)
        assert force <= damping_max * np.linalg.norm(moved - proxy) / model.sample_period_s \
            * (1 + 1e-6)
        proxy = moved
        forces.append(force)
        speeds.append(np.linalg.norm(out.tool_velocity_m_s[0]))
    # it cuts, and never beyond the steady force at the fastest speed reached: no spike
    assert 0.5 * damping_max * max(speeds) < max(forces) <= damping_max * max(speeds)


def test_resync_places_the_tool_at_the_handle_at_rest(paper_config) -> None:
    config = override(paper_config, "slave.environment", "linear")
    node = SlaveNode.from_config(config)
    state = node.initial_state(2)
    handle = np.array([[0.01, 0.0], [0.0, 0.0]])
    for _ in range(200):
        node.step(state, np.array([[1.0, 0.5], [0.0, 0.0]]), handle)
    node.safe_stop(state)
    target = np.array([[0.03, -0.002], [0.01, 0.02]])
    node.resync(state, target)
    assert np.allclose(node.tracking_error_m(state, target), 0.0)
    assert np.all(state.tool_velocity_m_s() == 0.0)
    assert np.all(state.compensator == 0.0) and np.all(state.tool_force_N == 0.0)
    node.resume(state)
    out = node.step(state, np.zeros((2, 2)), target)
    assert np.allclose(out.tool_position_m, target)  # at rest with no force: stays there


def test_a_standby_passivity_layer_is_the_paper_until_switched_on(model) -> None:
    """Paper mode builds the slave's TDPA layer switched off (the master's governor may switch
    it on): until then every lane steps exactly as the paper's node; a lane switched on
    damps the tool where the account lacks energy, the others stay the paper's, bit for bit."""
    from haptic.common.model.passivity import PassivitySettings

    scenario = load_scenario("constant-rate")
    paper = SlaveNode(model, scenario, "linear")
    standby = SlaveNode(model, scenario, "linear", passivity=PassivitySettings(),
                        passivity_standby=True)
    assert standby.passivity_standby and not paper.passivity_standby
    lanes = 3
    paper_state = paper.initial_state(lanes)
    standby_state = standby.initial_state(lanes)
    assert not standby_state.passivity.active.any()
    rng = np.random.default_rng(2)
    position = paper_state.handle_position_m.copy()
    differed = False
    for step in range(1500):
        if step == 500:
            mask = np.array([False, True, False])
            assert standby_state.passivity.switch(mask, True).tolist() == mask.tolist()
        force = rng.normal(0.0, 2.0, (lanes, 2))
        peer = np.full(lanes, 1e-6 * step)  # the master's cumulative energy, slowly
        expected = paper.step(paper_state, force, position)
        got = standby.step(standby_state, force, position, peer)
        same = expected.tool_position_m == got.tool_position_m
        if step < 500:
            assert same.all()
        else:
            assert same[[0, 2]].all()
            differed |= not same[1].all()
    assert differed and standby_state.passivity.dissipated_energy_J[1] > 0.0
    assert standby_state.passivity.dissipated_energy_J[[0, 2]].tolist() == [0.0, 0.0]
    # the master's energy was noted on every lane while off (monotone, counted once)
    assert standby_state.passivity.peer_sent_J.tolist() == pytest.approx([1e-6 * 1499] * 3)


def test_paper_mode_from_config_builds_the_layer_on_standby() -> None:
    config = load_config()
    node = SlaveNode.from_config(config)
    assert node.passivity is not None and node.passivity_standby
    assert not node.initial_state(1).passivity.active.any()
    tdpa = SlaveNode.from_config(override(config, "control.mode", "tdpa"))
    assert tdpa.passivity is not None and not tdpa.passivity_standby
    assert tdpa.initial_state(1).passivity.active.all()


def test_the_tdpa_tool_drifts_to_the_handle_and_its_speed_shows_it(model) -> None:
    """tdpa: at rest in free space with the handle 2 mm away (the controllers' leftover), the
    tool moves the gap times slave_drift_rate_per_s Ts in one step, capped at the speed limit,
    and its reported velocity is the plant's plus that step per period (the environment's
    force law sees the plant's own); a halted lane stays put, and with the rate 0 nothing moves."""
    from haptic.common.model.passivity import PassivitySettings

    scenario = load_scenario("constant-rate")
    ts = model.sample_period_s
    for rate, cap in ((2.0, 0.01), (50.0, 0.01), (0.0, 0.01)):
        node = SlaveNode(model, scenario, "linear", passivity=PassivitySettings(
            slave_drift_rate_per_s=rate, slave_drift_speed_max_m_per_s=cap,
            drift_stiffness_N_per_m=0.0))  # the spring off: the step alone
        state = node.initial_state(2)
        node.safe_stop(state, np.array([False, True]))
        handle = np.array([[0.002, 0.0], [0.002, 0.0]])
        out = node.step(state, np.zeros((2, 2)), handle, np.zeros(2))
        expected = min(0.002 * rate * ts, cap * ts)
        assert out.tool_position_m[0, 0] == pytest.approx(expected, rel=1e-9, abs=1e-15)
        assert out.tool_velocity_m_s[0, 0] == pytest.approx(expected / ts, rel=1e-9,
                                                            abs=1e-12)
        assert out.tool_position_m[1].tolist() == [0.0, 0.0]  # halted: held
        assert out.tool_position_m[0, 1] == 0.0
    # in free space (outside the clay) the gap closes at 2/s over 5 s (e^-10 of it left)
    # from an empty account; against the linear environment's spring it costs what the
    # account holds, none here, so it stops short of the handle
    ends = {}
    for environment in ("clay", "linear"):
        node = SlaveNode(model, scenario.with_grid(256, 64), environment, clay_impl="numpy",
                         passivity=PassivitySettings(drift_stiffness_N_per_m=0.0))
        state = node.initial_state(1)
        for _ in range(int(round(5.0 / ts))):
            out = node.step(state, np.zeros((1, 2)), np.array([[0.002, -0.001]]), np.zeros(1))
        assert state.passivity.tank_J[0] >= -1e-9  # nothing taken the port did not hold
        ends[environment] = np.abs(out.tracking_error_m).max()
    assert ends["clay"] <= 1e-6 and ends["linear"] > 1e-4, ends
