"""Model-mediated teleoperation (common/control/mmt.py and its kernels): the estimate
converges on a known spring and damper with noise, outlives a release and is dropped only when
the tool is inside it without force, skips clamped forces; the rendering of a constant model
is passive, a new contact found inside never jumps the force, and both kernels equal their
references on random inputs, non-finite ones included."""

from __future__ import annotations

import numpy as np
import pytest

from haptic.common.control.mmt import (
    EnvironmentModel,
    EstimatorSettings,
    EstimatorState,
    RendererSettings,
    RendererState,
    estimator_step_reference,
    renderer_step_reference,
)
from haptic.common.control.mmt_kernel import EstimatorKernel, RendererKernel

PERIOD_S = 0.001
WALL_M = 0.01
STIFFNESS_N_PER_M = 2000.0
DAMPING_N_S_PER_M = 10.0


def _press(seconds: float, rng: np.random.Generator, noise_N: float
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The tool pressed into a spring and damper wall at WALL_M along +x: 1 mm preload plus a
    1 mm, 2 Hz press; y free. (positions, velocities, forces with noise), each (steps, 1, 2)."""
    t = np.arange(int(round(seconds / PERIOD_S))) * PERIOD_S
    w = 2.0 * np.pi * 2.0
    x = WALL_M + 0.001 + 0.001 * (1.0 - np.cos(w * t))
    v = 0.001 * w * np.sin(w * t)
    f = STIFFNESS_N_PER_M * (x - WALL_M) + DAMPING_N_S_PER_M * v + rng.normal(0.0, noise_N,
                                                                              t.size)
    zeros = np.zeros_like(t)
    stack = [np.stack([a, b], axis=-1)[:, None, :] for a, b in ((x, zeros + 0.02), (v, zeros),
                                                                (f, zeros))]
    return stack[0], stack[1], stack[2]


def test_the_estimate_converges_on_a_known_spring_and_damper_with_noise() -> None:
    settings = EstimatorSettings(period_s=PERIOD_S)
    state = EstimatorState.create(np.zeros((1, 2)))
    rng = np.random.default_rng(21)
    positions, velocities, forces = _press(4.0, rng, noise_N=0.05)
    handle = np.zeros((1, 2))
    for x, v, f in zip(positions, velocities, forces, strict=True):
        _, model = estimator_step_reference(settings, state, x, v, f, handle, handle,
                                            np.array([True]))
    assert model.stiffness_N_per_m[0, 0] == pytest.approx(STIFFNESS_N_PER_M, rel=0.05)
    assert model.damping_N_s_per_m[0, 0] == pytest.approx(DAMPING_N_S_PER_M, rel=0.05)
    assert model.contact_position_m[0, 0] == pytest.approx(WALL_M, abs=1e-4)
    assert model.contact_side[0].tolist() == [1.0, 0.0]  # y touches nothing
    assert model.stiffness_N_per_m[0, 1] == 0.0


def _pressed_estimator(settings: EstimatorSettings) -> EstimatorState:
    """An estimator after a second of noiseless pressing into the wall."""
    state = EstimatorState.create(np.zeros((1, 2)))
    positions, velocities, forces = _press(1.0, np.random.default_rng(2), noise_N=0.0)
    handle = np.zeros((1, 2))
    for x, v, f in zip(positions, velocities, forces, strict=True):
        estimator_step_reference(settings, state, x, v, f, handle, handle, np.array([True]))
    return state


def _estimate(settings: EstimatorSettings, state: EstimatorState, x: float, f: float
              ) -> EnvironmentModel:
    handle = np.zeros((1, 2))
    return estimator_step_reference(settings, state, np.array([[x, 0.0]]), np.zeros((1, 2)),
                                    np.array([[f, 0.0]]), handle, handle, np.array([True]))[1]


def test_leaving_contact_keeps_the_model_until_the_tool_is_inside_it() -> None:
    """The wall is still there when the tool bounces off it: the master must keep rendering
    it; only a tool inside the modelled surface without force shows it gone."""
    settings = EstimatorSettings(period_s=PERIOD_S)
    state = _pressed_estimator(settings)
    kept = state.theta.copy()
    model = _estimate(settings, state, WALL_M + 0.0001, 0.2)  # above release_force_N: in
    assert state.touching[0, 0] == 1.0
    model = _estimate(settings, state, WALL_M - 0.002, 0.1)  # released, off the wall
    assert state.touching[0, 0] == 0.0 and model.contact_side[0, 0] == 1.0
    assert model.stiffness_N_per_m[0, 0] == pytest.approx(STIFFNESS_N_PER_M, rel=0.01)
    assert model.contact_position_m[0, 0] == pytest.approx(WALL_M, abs=1e-5)
    # touching again on the same side resumes the estimate (no prior, no new anchor)
    model = _estimate(settings, state, WALL_M + 0.0005, 1.0)
    assert model.stiffness_N_per_m[0, 0] == pytest.approx(STIFFNESS_N_PER_M, rel=0.01)
    assert abs(state.theta[0, 0, 0] - kept[0, 0, 0]) < 0.01 * STIFFNESS_N_PER_M
    # released, then inside the surface beyond the tolerance without force: no wall there
    _estimate(settings, state, WALL_M + 0.0005, 0.0)
    model = _estimate(settings, state, WALL_M + 0.0005 + settings.surface_tolerance_m, 0.0)
    assert model.contact_side[0, 0] == 0.0 and model.stiffness_N_per_m[0, 0] == 0.0
    assert not state.theta.any() and not state.covariance.any()
    # the next touch, on the other side, starts again from the prior
    model = _estimate(settings, state, 0.0, -1.0)
    assert model.contact_side[0, 0] == -1.0
    assert model.stiffness_N_per_m[0, 0] == settings.stiffness_prior_N_per_m


def test_the_fit_skips_forces_at_the_limit() -> None:
    """A clamped force does not fit the spring: the estimate keeps what it had."""
    settings = EstimatorSettings(period_s=PERIOD_S)
    state = _pressed_estimator(settings)
    kept = state.theta.copy()
    for depth in (0.03, 0.05, 0.08):  # 60 to 160 N on the 2 kN/m wall: clamped to 40 N
        _estimate(settings, state, WALL_M + depth, STIFFNESS_N_PER_M * depth)
    assert np.array_equal(state.theta, kept)
    _estimate(settings, state, WALL_M + 0.003, STIFFNESS_N_PER_M * 0.003 + 1.0)
    assert not np.array_equal(state.theta, kept)  # an unclamped sample is taken


def test_the_tool_tracks_the_newest_usable_handle_state() -> None:
    settings = EstimatorSettings(period_s=PERIOD_S, tracking_gain_per_s=40.0)
    state = EstimatorState.create(np.zeros((1, 2)))
    tool = np.array([[0.001, 0.0]])
    command, _ = estimator_step_reference(settings, state, tool, np.zeros((1, 2)),
                                          np.zeros((1, 2)), np.array([[0.003, 0.0]]),
                                          np.array([[0.01, 0.0]]), np.array([True]))
    assert command[0].tolist() == pytest.approx([0.01 + 40.0 * 0.002, 0.0])
    command, _ = estimator_step_reference(settings, state, tool, np.zeros((1, 2)),
                                          np.zeros((1, 2)), np.array([[np.nan, 0.0]]),
                                          np.array([[5.0, 0.0]]), np.array([True]))
    assert command[0].tolist() == pytest.approx([0.01 + 40.0 * 0.002, 0.0])  # held


def _model(lanes: int, stiffness: float, damping: float, position: float, side: float
           ) -> EnvironmentModel:
    full = np.full((lanes, 2), 0.0)
    return EnvironmentModel(full + stiffness, full + damping, full + position, full + side)


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_rendering_a_constant_model_is_passive(side: float) -> None:
    """A random operator force biased into the wall (on both axes), hard pushes in and out
    now and then: the operator's work always covers the handle's kinetic energy plus the
    wall's spring energy (the implicit step), so the wall gives back nothing it did not
    take."""
    settings = RendererSettings(period_s=PERIOD_S, handle_damping_N_s_per_m=5.0)
    model = _model(1, 20000.0, 0.5, 0.002 * side, side)
    state = RendererState.create(np.zeros((1, 2)))
    rng = np.random.default_rng(8)
    work = 0.0
    deepest = 0.0
    for step in range(20000):
        force = rng.normal(0.0, 6.0, (1, 2)) + 3.0 * side
        if step % 2000 < 50:
            force *= 10.0  # hard pushes into the wall and out of it
        before = state.position_m.copy()
        renderer_step_reference(settings, state, force, model, np.array([step == 0]))
        work += float(np.sum(np.clip(force, -40.0, 40.0) * (state.position_m - before)))
        depth = np.maximum(side * (state.position_m[0] - 0.002 * side), 0.0)
        energy = (0.5 * settings.handle_mass_kg * float(np.sum(state.velocity_m_per_s ** 2))
                  + 0.5 * 20000.0 * float(np.sum(depth ** 2)))
        assert work >= energy - 1e-12
        assert np.all(np.abs(state.position_m) < settings.position_limit_m)
        deepest = max(deepest, float(depth.max()))
    assert deepest > 0.0  # the wall was reached


def test_a_new_contact_found_inside_starts_its_surface_at_the_handle() -> None:
    """The handle walked 40 mm into the wall while the touch travelled back: the first model
    must not throw it out with k p (80 N here); its surface starts at the handle and moves
    to the received one at most surface_rate_m_per_s."""
    settings = RendererSettings(period_s=PERIOD_S, surface_rate_m_per_s=0.05)
    state = RendererState.create(np.array([[0.05, 0.0]]))
    model = _model(1, 2000.0, 0.0, 0.01, 1.0)
    model.contact_side[0, 1] = 0.0
    forces = []
    for step in range(1000):
        _, _, force = renderer_step_reference(settings, state, np.zeros((1, 2)), model,
                                              np.array([step == 0]))
        forces.append(-force[0, 0])
        travel = abs(state.contact_position_m[0, 0] - 0.05)
        assert travel <= settings.surface_rate_m_per_s * PERIOD_S * (step + 1) + 1e-15
    assert forces[0] < 0.5
    assert max(forces) < 2000.0 * 0.04 / 2.0  # never the received surface's k p
    assert np.all(np.diff(forces) < 2000.0 * settings.surface_rate_m_per_s * PERIOD_S + 1e-9)
    assert state.target_position_m[0, 0] == 0.01
    assert state.contact_position_m[0, 0] == pytest.approx(0.01)  # 40 mm at 50 mm/s: 0.8 s


def test_an_empty_model_renders_the_free_handle() -> None:
    settings = RendererSettings(period_s=PERIOD_S, handle_mass_kg=0.2,
                                handle_damping_N_s_per_m=4.0)
    state = RendererState.create(np.zeros((1, 2)))
    for _ in range(3000):
        _, velocity, force = renderer_step_reference(settings, state, np.array([[2.0, -1.0]]),
                                                     EnvironmentModel.none(1), np.array([True]))
    assert velocity[0].tolist() == pytest.approx([0.5, -0.25], rel=1e-6)
    assert not force.any()


def test_the_model_travels_as_message_fields() -> None:
    model = _model(2, 1500.0, 3.0, 0.004, -1.0)
    fields = model.to_fields(1)
    assert set(fields) == {"stiffness_N_per_m", "damping_N_s_per_m", "contact_position_m",
                           "contact_side"}
    back = EnvironmentModel.from_fields(fields)
    for a, b in zip(back, model, strict=True):
        assert a[0].tolist() == b[1].tolist()


def test_the_estimator_kernel_equals_the_reference_on_random_inputs() -> None:
    settings = EstimatorSettings(period_s=PERIOD_S, covariance_trace_max=1e7,
                                 forgetting_factor=0.99)
    lanes = 6
    rng = np.random.default_rng(31)
    start = rng.normal(0.0, 0.01, (lanes, 2))
    reference = EstimatorState.create(start)
    kernel = EstimatorKernel(settings, start)
    contacts = 0
    for step in range(1500):
        x = rng.normal(0.0, 0.002, (lanes, 2))
        v = rng.normal(0.0, 0.02, (lanes, 2))
        in_contact = (step // 100 + np.arange(lanes)) % 3 != 0
        f = np.where(in_contact[:, None], 1500.0 * x + 3.0 + rng.normal(0.0, 0.1, (lanes, 2)),
                     rng.normal(0.0, 0.05, (lanes, 2)))
        hx = rng.normal(0.0, 0.01, (lanes, 2))
        hv = rng.normal(0.0, 0.05, (lanes, 2))
        fresh = rng.random(lanes) > 0.3
        if step % 60 == 5:
            x[0, 0] = np.nan
            v[1, 1] = np.inf
            f[2, 0] = -np.inf
            hx[3, 1] = np.nan
            hv[4, 0] = np.inf
            f[5, 1] = 1e300
        expected = estimator_step_reference(settings, reference, x, v, f, hx, hv, fresh)
        command, model = kernel.step(x, v, f, hx, hv, fresh)
        assert np.all(np.isfinite(command))
        np.testing.assert_allclose(command, expected[0], rtol=1e-12, atol=1e-12)
        for a, b in zip(model, expected[1], strict=True):
            assert np.all(np.isfinite(a))
            np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12)
        contacts += int(np.count_nonzero(model.contact_side))
    for name in ("theta", "covariance", "anchor_m", "side", "handle_position_m",
                 "handle_velocity_m_per_s", "touching"):
        np.testing.assert_allclose(getattr(kernel.state, name), getattr(reference, name),
                                   rtol=1e-9, atol=1e-9, err_msg=name)
    assert contacts > 1000


def test_the_renderer_kernel_equals_the_reference_on_random_inputs() -> None:
    settings = RendererSettings(period_s=PERIOD_S, position_limit_m=0.1)
    lanes = 6
    rng = np.random.default_rng(41)
    start = rng.normal(0.0, 0.002, (lanes, 2))
    reference = RendererState.create(start)
    kernel = RendererKernel(settings, start)
    pushed = 0
    for step in range(2000):
        force = rng.normal(0.0, 8.0, (lanes, 2))
        side = rng.choice([-1.0, 0.0, 1.0], (lanes, 2))
        model = EnvironmentModel(rng.uniform(0.0, 5000.0, (lanes, 2)),
                                 rng.uniform(0.0, 20.0, (lanes, 2)),
                                 rng.normal(0.0, 0.003, (lanes, 2)), side)
        fresh = rng.random(lanes) > 0.9
        if step % 70 == 9:
            force[0, 0] = np.nan
            model.stiffness_N_per_m[1, 0] = np.inf
            model.damping_N_s_per_m[2, 1] = np.nan
            model.contact_position_m[3, 0] = -np.inf
            model.contact_side[4, 1] = 0.5  # not a side
            model.stiffness_N_per_m[5, 0] = -3.0  # out of range
        expected = renderer_step_reference(settings, reference, force, model, fresh)
        got = kernel.step(force, model, fresh)
        for a, b in zip(got, expected, strict=True):
            assert np.all(np.isfinite(a))
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)
        pushed += int(np.count_nonzero(got[2]))
    for name in ("position_m", "velocity_m_per_s", "stiffness_N_per_m", "damping_N_s_per_m",
                 "contact_position_m", "contact_side", "target_position_m"):
        np.testing.assert_allclose(getattr(kernel.state, name), getattr(reference, name),
                                   rtol=1e-12, atol=1e-12, err_msg=name)
    assert pushed > 100  # the model did push back
