"""The master node's Warp kernel against an independent numpy oracle of the same law.

The oracle below is the safety layer and compensator written with numpy array calls, step by
step as docs/master.md states them (the implementation the kernel replaced). Random input
sequences with NaNs, force and speed trips, saturations, the gate and the ramp, and stacked
per-lane compensators must give the same commands, states, used forces and events.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
import pytest

from haptic.common.config import load_config
from haptic.common.model.lti import DiscreteLTI
from haptic.lockstep.stacked import StackedLTI
from haptic.master.node import (
    AXES,
    COMPENSATOR_INPUTS,
    COMPENSATOR_OUTPUTS,
    MasterNode,
    SafetyEvent,
    master_compensator,
)
from haptic.master.settings import SafetySettings, master_settings

_LIMITS = ("handle force", "tool force", "command velocity", "workspace")


@dataclass
class ReferenceState:
    """Per-lane state, lanes first."""

    compensator: np.ndarray
    origin_m: np.ndarray
    last_command_m: np.ndarray
    last_position_m: np.ndarray
    hold_m: np.ndarray
    small_force_count: np.ndarray
    forces_enabled: np.ndarray
    ramp_elapsed_s: np.ndarray
    force_scale: np.ndarray
    faulted: np.ndarray
    limiting: np.ndarray
    step: int = 0
    events: list[SafetyEvent] = field(default_factory=list)
    used_N: np.ndarray | None = None  # (lanes, 4) what the compensator used, zero if faulted


class ReferenceMasterNode:
    """The master node's law in plain numpy, as it was before the Warp kernel: the oracle."""

    def __init__(self, compensator: DiscreteLTI, safety: SafetySettings) -> None:
        if compensator.input_names != COMPENSATOR_INPUTS or (
            compensator.output_names != COMPENSATOR_OUTPUTS
        ):
            raise ValueError("compensator must map [fh_x, fh_y, ft_x, ft_y] to [vh_x, vh_y]")
        self.compensator = compensator
        self.safety = safety
        self.period_s = compensator.period_s
        self._workspace_min = np.asarray(safety.workspace_min_m, float)
        self._workspace_max = np.asarray(safety.workspace_max_m, float)

    def activate(self, position_m: np.ndarray) -> ReferenceState:
        """A fresh state for lanes starting at ``position_m`` (lanes, 2): the command holds
        that position, forces are not yet enabled."""
        position = np.array(np.atleast_2d(position_m), float)
        lanes = position.shape[0]
        faulted = ~np.all(np.isfinite(position), axis=1)
        safe = np.nan_to_num(position)
        state = ReferenceState(
            compensator=self.compensator.initial_state(lanes), origin_m=safe.copy(),
            last_command_m=safe.copy(), last_position_m=safe.copy(), hold_m=safe.copy(),
            small_force_count=np.zeros(lanes, int), forces_enabled=np.zeros(lanes, bool),
            ramp_elapsed_s=np.zeros(lanes), force_scale=np.zeros(lanes),
            faulted=np.zeros(lanes, bool), limiting=np.zeros((lanes, len(_LIMITS), 2), bool),
        )
        for lane in np.flatnonzero(faulted):
            self._trip(state, lane, "non-finite handle position at activation", None)
        return state

    def trip(self, state: ReferenceState, lanes: np.ndarray, reason: str) -> None:
        """Put ``lanes`` (bool mask or indices) in the safe state for an outside reason
        (a drive fault, a missing PDO); an event records ``reason``."""
        for lane in np.flatnonzero(_mask(lanes, len(state.faulted))):
            self._trip(state, int(lane), reason, None)

    def _trip(self, state: ReferenceState, lane: int, reason: str, axis: str | None) -> None:
        if state.faulted[lane]:
            return
        state.faulted[lane] = True
        state.hold_m[lane] = state.last_position_m[lane]
        state.events.append(SafetyEvent(state.step, state.step * self.period_s, lane, "trip",
                                        reason, axis))

    def step(
        self,
        state: ReferenceState,
        handle_force_N: np.ndarray,
        handle_position_m: np.ndarray,
        tool_force_recv_N: np.ndarray,
    ) -> np.ndarray:
        """One period: returns the handle position command (lanes, 2), m, always finite.

        ``handle_force_N``: fh measured by the sensor (N); ``handle_position_m``: yh from
        the encoders (m); ``tool_force_recv_N``: the tool force received from the slave (N),
        zero when there is none.
        """
        safety = self.safety
        fh = np.asarray(handle_force_N, float)
        yh = np.asarray(handle_position_m, float)
        ft = np.asarray(tool_force_recv_N, float)
        period = self.period_s

        # 1. Non-finite inputs: the lane trips and holds its last finite position.
        fh_ok, yh_ok, ft_ok = np.isfinite(fh), np.isfinite(yh), np.isfinite(ft)
        if not (fh_ok.all() and yh_ok.all() and ft_ok.all()):
            for name, ok in (("handle force", fh_ok), ("handle position", yh_ok),
                             ("tool force", ft_ok)):
                self._trip_where(state, ~ok, f"non-finite {name}")
        measured = np.where(yh_ok, yh, state.last_position_m)
        velocity = (measured - state.last_position_m) / period
        state.last_position_m[...] = measured
        fh = np.where(fh_ok, fh, 0.0)
        ft = np.where(ft_ok, ft, 0.0)

        # 2. Trips on measured force, speed and position.
        self._trip_where(state, np.abs(fh) > safety.force_trip_N,
                         f"handle force beyond {safety.force_trip_N:g} N")
        self._trip_where(state, np.abs(velocity) > safety.velocity_trip_m_per_s,
                         f"handle speed beyond {safety.velocity_trip_m_per_s:g} m/s")
        margin = safety.workspace_trip_margin_m
        outside = (measured < self._workspace_min - margin) | (
            measured > self._workspace_max + margin)
        self._trip_where(state, outside, "handle outside the workspace")

        # 3. Force saturation.
        limit = safety.force_limit_N
        self._note_limits(state, 0, np.abs(fh) > limit, f"handle force saturated at {limit:g} N")
        self._note_limits(state, 1, np.abs(ft) > limit, f"tool force saturated at {limit:g} N")
        fh = np.minimum(np.maximum(fh, -limit), limit)
        ft = np.minimum(np.maximum(ft, -limit), limit)

        # 4. Force ramp after activation.
        small = np.all(np.abs(fh) < safety.ramp_small_force_N, axis=1)
        waiting = ~state.forces_enabled & ~state.faulted
        state.small_force_count[...] = np.where(small, state.small_force_count + 1, 0)
        opening = waiting & (state.small_force_count >= safety.ramp_small_samples)
        state.forces_enabled |= opening
        for lane in np.flatnonzero(opening) if opening.any() else ():
            state.events.append(SafetyEvent(state.step, state.step * period, int(lane),
                                            "enable", "forces enabled after "
                                            f"{safety.ramp_small_samples} small-force samples"))
        if safety.ramp_time_s > 0.0:
            scale = np.clip(state.ramp_elapsed_s / safety.ramp_time_s, 0.0, 1.0)
        else:
            scale = np.ones_like(state.ramp_elapsed_s)
        scale = np.where(state.forces_enabled, scale, 0.0)
        state.ramp_elapsed_s += np.where(state.forces_enabled, period, 0.0)
        state.force_scale[...] = scale

        # The compensator: a position offset from the origin; frozen in faulted lanes.
        inputs = scale[:, None] * np.concatenate([fh, ft], axis=1)
        state.used_N = np.where(state.faulted[:, None], 0.0, inputs)
        any_faulted = bool(state.faulted.any())
        if any_faulted:
            frozen = state.compensator[state.faulted].copy()
        offset = self.compensator.step(state.compensator, inputs)
        if any_faulted:
            state.compensator[state.faulted] = frozen
        raw = state.origin_m + offset

        # 5. Command rate and workspace limits, re-basing the offset when they act.
        max_step = safety.velocity_limit_m_per_s * period
        delta = raw - state.last_command_m
        self._note_limits(state, 2, np.abs(delta) > max_step,
                          f"command rate limited to {safety.velocity_limit_m_per_s:g} m/s")
        command = state.last_command_m + np.minimum(np.maximum(delta, -max_step), max_step)
        outside_box = (command < self._workspace_min) | (command > self._workspace_max)
        self._note_limits(state, 3, outside_box, "command clamped to the workspace")
        command = np.minimum(np.maximum(command, self._workspace_min), self._workspace_max)
        state.origin_m += command - raw

        command = np.where(state.faulted[:, None], state.hold_m, command)
        state.last_command_m[...] = command
        state.step += 1
        return command.copy()

    def _trip_where(self, state: ReferenceState, condition: np.ndarray, reason: str) -> None:
        if not condition.any():
            return
        for lane, axis in zip(*np.nonzero(condition), strict=True):
            self._trip(state, int(lane), reason, AXES[axis])

    def _note_limits(self, state: ReferenceState, which: int, active: np.ndarray,
                     reason: str) -> None:
        starting = active & ~state.limiting[:, which, :] & ~state.faulted[:, None]
        state.limiting[:, which, :] = active
        if not starting.any():
            return
        for lane, axis in zip(*np.nonzero(starting), strict=True):
            state.events.append(SafetyEvent(state.step, state.step * self.period_s, int(lane),
                                            "saturate", reason, AXES[axis]))


def _mask(lanes: np.ndarray, count: int) -> np.ndarray:
    lanes = np.asarray(lanes)
    if lanes.dtype == bool:
        return lanes
    mask = np.zeros(count, bool)
    mask[lanes.astype(int)] = True
    return mask


# --- the kernel against the oracle --------------------------------------------------------

STATE_FIELDS = ("compensator", "origin_m", "last_command_m", "last_position_m", "hold_m",
                "small_force_count", "forces_enabled", "ramp_elapsed_s", "force_scale",
                "faulted", "limiting")


def _safety(**changes) -> SafetySettings:
    base = master_settings(load_config()).safety
    return dataclasses.replace(base, **changes)


def _inputs(rng: np.random.Generator, steps: int, lanes: int) -> tuple[np.ndarray, ...]:
    """Forces that cross the gate, the saturation and the trip; positions that jump, leave
    the box and turn NaN; a few non-finite samples in every signal."""
    fh = rng.normal(0.0, 0.3, (steps, lanes, 2))
    fh[steps // 4:] += rng.normal(0.0, 12.0, (steps - steps // 4, lanes, 2))
    walk = np.cumsum(rng.normal(0.0, 2e-4, (steps, lanes, 2)), axis=0)
    yh = walk + rng.choice([0.0, 0.0, 0.0, 1e-3], (steps, lanes, 2))
    ft = rng.normal(0.0, 15.0, (steps, lanes, 2))
    for signal, value in ((fh, np.nan), (yh, np.nan), (ft, np.inf), (fh, 200.0)):
        hits = rng.random((steps, lanes, 2)) < 0.002
        signal[hits] = value
    return fh, yh, ft


def _compare(node: MasterNode, oracle: ReferenceMasterNode, start: np.ndarray,
             inputs: tuple[np.ndarray, ...]) -> None:
    state, expected = node.initial_state(start), oracle.activate(start)
    for fh, yh, ft in zip(*inputs, strict=True):
        command = node.step(state, fh, yh, ft)
        reference = oracle.step(expected, fh, yh, ft)
        np.testing.assert_allclose(command, reference, rtol=1e-9, atol=1e-12)
        used = np.concatenate([state.handle_force_used_N, state.tool_force_used_N], axis=1)
        np.testing.assert_allclose(used, expected.used_N, rtol=1e-12, atol=1e-12)
    for name in STATE_FIELDS:
        np.testing.assert_allclose(getattr(state, name), getattr(expected, name), rtol=1e-9,
                                   atol=1e-12, err_msg=name)
    assert [(e.step, e.lane, e.kind, e.reason, e.axis) for e in state.events] == [
        (e.step, e.lane, e.kind, e.reason, e.axis) for e in expected.events]
    assert state.step == expected.step


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_kernel_matches_the_numpy_oracle_on_random_inputs(paper_model, seed) -> None:
    rng = np.random.default_rng(seed)
    safety = _safety(ramp_small_samples=5, ramp_time_s=0.01, velocity_trip_m_per_s=3.0,
                     velocity_limit_m_per_s=0.2, workspace_min_m=(-0.004, -0.01),
                     workspace_max_m=(0.004, 0.01), workspace_trip_margin_m=0.002)
    block = master_compensator(paper_model)
    lanes = 6
    start = rng.normal(0.0, 1e-3, (lanes, 2))
    _compare(MasterNode(block, safety), ReferenceMasterNode(block, safety), start,
             _inputs(rng, 1500, lanes))


def test_kernel_matches_the_oracle_with_one_compensator_per_lane(paper_model) -> None:
    rng = np.random.default_rng(7)
    gains = [1.0, 5.0, 13.0]
    block = StackedLTI.from_blocks([master_compensator(paper_model.with_gain(k))
                                    for k in gains])
    safety = _safety(ramp_small_samples=3, ramp_time_s=0.0)
    start = np.zeros((len(gains), 2))
    start[1, 0] = np.nan  # a lane that cannot start: tripped at activation
    _compare(MasterNode(block, safety), ReferenceMasterNode(block, safety), start,
             _inputs(rng, 800, len(gains)))


def test_used_forces_are_what_the_compensator_integrated(paper_model) -> None:
    """The master sends the used handle force to the slave: saturated, scaled by the ramp,
    zero once the lane has tripped."""
    safety = _safety(ramp_small_samples=2, ramp_time_s=0.01, force_limit_N=5.0)
    node = MasterNode.from_model(paper_model, safety)
    state = node.initial_state(np.zeros((1, 2)))
    for _ in range(2):
        node.step(state, np.zeros((1, 2)), np.zeros((1, 2)), np.zeros((1, 2)))
    assert state.forces_enabled[0]
    scales = []
    for _ in range(40):
        node.step(state, np.array([[8.0, -2.0]]), np.zeros((1, 2)), np.array([[-9.0, 1.0]]))
        scale = state.force_scale[0]
        scales.append(scale)
        np.testing.assert_allclose(state.handle_force_used_N[0], [5.0 * scale, -2.0 * scale])
        np.testing.assert_allclose(state.tool_force_used_N[0], [-5.0 * scale, 1.0 * scale])
    assert 0.0 < scales[0] < scales[5] < 1.0 and scales[-1] == 1.0
    node.step(state, np.array([[np.nan, 0.0]]), np.zeros((1, 2)), np.zeros((1, 2)))
    assert state.faulted[0]
    np.testing.assert_array_equal(state.handle_force_used_N[0], [0.0, 0.0])
    np.testing.assert_array_equal(state.tool_force_used_N[0], [0.0, 0.0])


def test_step_inputs_reads_the_state_buffer_and_returns_a_live_view(paper_model) -> None:
    node = MasterNode.from_model(paper_model, _safety(ramp_small_samples=1, ramp_time_s=0.0))
    state = node.initial_state(np.zeros((1, 2)))
    state.inputs[0] = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    node.step_inputs(state)
    state.inputs[0] = (2.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    view = node.step_inputs(state)
    first = view.copy()
    for _ in range(50):
        node.step_inputs(state)
    assert view[0, 0] > first[0, 0] > 0.0  # Ch1 integrates the push; the view follows


def test_the_program_tick_and_the_lockstep_lanes_step_the_same_law(paper_model) -> None:
    """The real-time tick writes one lane's six inputs and calls step_inputs; the lockstep
    simulator steps every lane with step(): lane by lane, the same commands and used forces,
    bit for bit."""
    rng = np.random.default_rng(3)
    safety = _safety(ramp_small_samples=4, ramp_time_s=0.005)
    node = MasterNode.from_model(paper_model, safety)
    lanes, steps = 3, 400
    fh, yh, ft = _inputs(rng, steps, lanes)
    start = np.zeros((lanes, 2))
    together = node.initial_state(start)
    alone = [node.initial_state(start[lane:lane + 1]) for lane in range(lanes)]
    for k in range(steps):
        commands = node.step(together, fh[k], yh[k], ft[k])
        for lane, state in enumerate(alone):
            state.inputs[0] = (*fh[k, lane], *yh[k, lane], *ft[k, lane])
            command = node.step_inputs(state)[0]
            np.testing.assert_array_equal(command, commands[lane])
            np.testing.assert_array_equal(state.handle_force_used_N[0],
                                          together.handle_force_used_N[lane])
            np.testing.assert_array_equal(state.tool_force_used_N[0],
                                          together.tool_force_used_N[lane])
    for lane, state in enumerate(alone):
        assert [(e.kind, e.reason, e.axis) for e in state.events] == [
            (e.kind, e.reason, e.axis) for e in together.events if e.lane == lane]
