"""The comparison's cells of the paper's scheme and of TDPA, run by the lockstep simulator.

These two controls are the programs' own node kernels (master/node.py, slave_sim/node.py with
the synthesised compensators, the TDPA layer of common/model/passivity.py), so the comparison
calls :class:`~haptic.lockstep.simulator.LockstepSimulator` rather than re-deriving their laws
as a two-port: what is compared is what the programs run. Its environment is the linear one
(``ft = Tt yt``), with ``Tt`` set per task:

- free-sine: ``Tt = 0``, the rig's tracking operator following the same sine with the same
  spring and damper as the lane simulator's hand;
- wall: ``Tt = k``, a spring of the wall's stiffness from the tool's start (contact from the
  first sample: no approach and no impact; the one-sided wall is not a linear environment),
  the rig's constant operator ramping the same intent force through the model's operator
  impedance ``Th`` (the paper's, also the lane simulator's hand).

- clay-cut: the paper's constant-rate cut (the constant-rate scenario's Warp clay, a 10 cm
  block at 100 N s/m), the operator the clay sweep's steady 3.6 N push brought in over 1 s
  (lockstep/sweep.py), the paper's 3.6 N at 38 mm/s beside it.

For free-sine and the wall the loop is then linear and exactly the one the paper's sampled
Nyquist analysis (common/analysis, lockstep/sweep.py's ``analytic_margin_s``) judges, which the
report sets beside the measurement. Every lane records the task axis into the comparison's
:class:`~haptic.lockstep.compare_records.LaneRecords`; the lines carry the same schedules as
the lane simulator's (lockstep/compare_links.py, the same timing).
"""

from __future__ import annotations

import numpy as np

from haptic.common.config.scenario import load_scenario
from haptic.common.model.passivity import PassivitySettings
from haptic.common.model.teleop import TeleopModel
from haptic.lockstep.compare_grid import CompareGrid, Lane
from haptic.lockstep.compare_links import lane_schedules, round_trip_samples
from haptic.lockstep.compare_records import RECORD_STRIDE, LaneRecords
from haptic.lockstep.simulator import LockstepSimulator
from haptic.lockstep.sweep import CLAY_OPERATOR
from haptic.master.simulated_rig.operator import parse_operator_spec

PAPER_CONTROLS = ("paper", "tdpa")
#: Lanes per simulation: the full traces of a part are kept, (steps, lanes, 2) for each of
#: the simulator's trace names.
PART_LANES = 64


def task_model(model: TeleopModel, task: str, stiffness_N_per_m: float) -> TeleopModel:
    """The model with the task's environment: ``Tt = 0`` (free-sine) or ``Tt = k`` (wall);
    the clay cut's is the clay's, the model as configured."""
    if task == "clay-cut":
        return model
    tt = np.array([stiffness_N_per_m if task == "wall" else 0.0])
    axes = tuple(axis.with_environment(tt) for axis in model.axes)
    return TeleopModel(model.sample_period_s, model.ch1_gain_k, model.ch1_num, model.ch1_den,
                       axes)


def operator_spec(grid: CompareGrid, task: str) -> str:
    """The rig's operator for the task (see the module's docstring)."""
    settings = grid.task
    if task == "clay-cut":
        return CLAY_OPERATOR
    if task == "wall":
        return (f"constant:fx={settings.push_force_N},fy=0,onset=0,"
                f"rise={0.5 * grid.duration_s}")
    return (f"track:shape=sine,ax={settings.sine_amplitude_m},ay=0,"
            f"freq={settings.sine_frequency_hz},kp={settings.track_stiffness_N_per_m},"
            f"kd={settings.track_damping_N_s_per_m},max=1000")


def _fill(records: LaneRecords, columns: np.ndarray, traces: dict[str, np.ndarray],
          diverged: np.ndarray) -> None:
    """Copy a part's traces (task axis) into the records' ``columns``."""
    stride = records.stride
    names = (("handle_position_m", "handle_position_m"), ("tool_position_m", "tool_position_m"),
             ("handle_force_N", "handle_force_N"), ("environment_force_N", "tool_force_N"))
    with np.errstate(invalid="ignore"):
        for target, source in names:
            getattr(records, target)[:, columns] = traces[source][::stride, :, 0]
        peak = np.fmax(np.nanmax(np.abs(traces["handle_force_N"][:, :, 0]), axis=0),
                       np.nanmax(np.abs(traces["tool_force_N"][:, :, 0]), axis=0))
    finite = np.all(np.isfinite(np.stack([traces[source][:, :, 0] for _, source in names])),
                    axis=(0, 1))
    records.peak_force_N[columns] = np.where(finite, peak, np.inf)
    records.non_finite[columns] = ~finite | diverged


def simulate_paper_lanes(control: str, lanes: list[Lane], grid: CompareGrid,
                         model: TeleopModel) -> LaneRecords:
    """Run ``control`` ("paper" or "tdpa") on every lane for the grid's duration, one
    simulation per (task, stiffness) and part of PART_LANES lanes."""
    if control not in PAPER_CONTROLS:
        raise ValueError(f"control must be one of {', '.join(PAPER_CONTROLS)}")
    period = model.sample_period_s
    steps = int(round(grid.duration_s / period))
    records = LaneRecords.create(period, steps, len(lanes), RECORD_STRIDE)
    handle_schedule, tool_schedule = lane_schedules(lanes, steps, period, grid.seed)
    delays = round_trip_samples(lanes, period)
    scenario = load_scenario("constant-rate")
    passivity = PassivitySettings() if control == "tdpa" else None
    groups: dict[tuple[str, float], list[int]] = {}
    for index, lane in enumerate(lanes):
        groups.setdefault((lane.task, lane.wall_stiffness_N_per_m), []).append(index)
    for (task, stiffness), members in groups.items():
        operator = parse_operator_spec(operator_spec(grid, task))
        environment = "clay" if task == "clay-cut" else "linear"
        modelled = task_model(model, task, stiffness)
        for first in range(0, len(members), PART_LANES):
            columns = np.asarray(members[first:first + PART_LANES])
            simulator = LockstepSimulator(modelled, scenario, operator,
                                          np.full(columns.size, model.ch1_gain_k), environment,
                                          device="cpu", passivity=passivity)
            result = simulator.run(grid.duration_s, delays[columns],
                                   record_lanes=np.arange(columns.size),
                                   schedules=(handle_schedule[:, columns],
                                              tool_schedule[:, columns]))
            _fill(records, columns, result.traces, result.diverged)
    return records


__all__ = ["PAPER_CONTROLS", "operator_spec", "simulate_paper_lanes",
           "task_model"]
