"""The lockstep simulator: the master node, the simulated rig with its operator, and the slave
node stepped together in one process, joined by exact sample delay lines.

One tick k (period Ts), every lane at once (docs/lockstep.md derives the timing):

1. the tool line delivers the newest tool force the master may have (``ft_recv``);
2. the rig steps (:meth:`RigModel.step`): it applies the command the master wrote at tick
   k-1 and samples the handle at SYNC k; the operator model feels ``ft_recv``;
3. the master node maps (fh, yh, ft_recv) to the handle command (applied at SYNC k+1);
4. the handle line takes (fh, yh) sent at tick k and delivers to the slave the newest
   message it may have (d1 samples old);
5. the slave node steps: compensators, tool, environment; the tool force it computes
   describes the end of its step (t_{k+1}) and enters the tool line stamped so.

With round-trip delay n samples split d1 = n // 2 to the slave and d2 = n - d1 back, this is
exactly the loop :class:`~haptic.common.analysis.loop.AxisLoop` analyses with
``sample_period_s`` = Ts at tau = n Ts, and the loop :mod:`haptic.common.analysis.linear_loop`
simulates (with the linear environment and the safety layer out of the way).

Lanes may differ in the Ch1 gain k (the compensators are stacked per lane) and in their
delays; everything random comes from one seeded generator, so a run is bit-for-bit
reproducible.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

from haptic.common.config.scenario import Scenario
from haptic.common.model.drift import DriftCoupling
from haptic.common.model.lti import DiscreteLTI
from haptic.common.model.passivity import PassivitySettings
from haptic.common.model.synthesis import synthesize
from haptic.common.model.teleop import TeleopModel
from haptic.common.model.work_area import shared_work_area, slave_work_area_m
from haptic.common.runtime.gc_pauses import frozen_heap
from haptic.common.wire.injection import InjectionConfig
from haptic.common.wire.messages import Flags
from haptic.lockstep.delay_line import source_schedule
from haptic.lockstep.environments import ENVIRONMENTS
from haptic.lockstep.governed import GovernedLanes
from haptic.lockstep.message_lines import (
    HandleLine,
    HandleMessages,
    ToolLine,
    ToolMessages,
    handle_line,
    tool_line,
)
from haptic.lockstep.quiet_lanes import MasterQuietLanes, SlaveQuietLanes
from haptic.lockstep.stacked import StackedLTI
from haptic.master.margin_governor import MarginGovernor
from haptic.master.node import MasterNode, master_compensator
from haptic.master.settings import SafetySettings, with_work_area
from haptic.master.simulated_rig.operator import OperatorModel
from haptic.master.simulated_rig.rig_block import RigModel
from haptic.master.supervisor import MasterSupervisor
from haptic.master.tick import MasterTick
from haptic.slave_sim.clay.sim import ClayStepResult
from haptic.slave_sim.environment import LinearEnvironment, make_environment
from haptic.slave_sim.input_guard import InputGuard, InputGuardSettings
from haptic.slave_sim.node import SlaveNode, slave_compensators
from haptic.slave_sim.resync import ToolResync
from haptic.slave_sim.supervisor import SlaveSupervisor
from haptic.slave_sim.tick import SlaveTick

#: Safety settings that never act on a sweep's signals: the lockstep compares the loop with
#: the analysis, which has no saturation, ramp or trip (docs/lockstep.md).
TRANSPARENT_SAFETY = SafetySettings(
    force_limit_N=1e12, force_trip_N=1e15, velocity_limit_m_per_s=1e12,
    velocity_trip_m_per_s=1e15, workspace_min_m=(-1e12, -1e12), workspace_max_m=(1e12, 1e12),
    workspace_trip_margin_m=1e12, ramp_small_force_N=1e14, ramp_small_samples=1,
    ramp_time_s=0.0,
)


@dataclass(frozen=True)
class LockstepSupervision:
    """What the lanes' supervisors and input guards act on (master/supervisor.py,
    slave_sim/supervisor.py, slave_sim/input_guard.py): the watchdog's ``max_message_age_s``
    (s) and ``resync_messages``, the resync's ``sync_tolerance_m`` (m), the slave's work area
    (``work_area_m``: x_low, x_high, y_low, y_high, m, margin included; ``grid_m`` the area
    the handle must be back over to end a work-area stop, or None) and its input bounds."""

    max_message_age_s: float
    resync_messages: int
    sync_tolerance_m: float
    work_area_m: tuple[float, float, float, float]
    input_guard: InputGuardSettings
    grid_m: tuple[float, float, float, float] | None = None

    @classmethod
    def from_config(cls, config: dict[str, Any], scenario: Scenario) -> LockstepSupervision:
        """The deployed programs' settings: ``[link]``'s watchdog, the slave's work area
        about the scenario's grid and ``[slave.safety]``."""
        from haptic.common.runtime.watchdog import DEFAULT_SYNC_TOLERANCE_M

        watchdog = config["link"]["watchdog"]
        grid = scenario.grid
        return cls(float(watchdog["max_message_age_s"]), int(watchdog["resync_messages"]),
                   DEFAULT_SYNC_TOLERANCE_M, slave_work_area_m(grid.x_range_m, grid.y_range_m),
                   InputGuardSettings.from_config(config),
                   (grid.x_range_m[0], grid.x_range_m[1], grid.y_range_m[0], grid.y_range_m[1]))


#: Supervision that never acts on a sweep's signals (as :data:`TRANSPARENT_SAFETY`): the
#: supervisors and guards run every tick, but no silence, work area or input bound is ever
#: reached; a non-finite input still faults the guard, as it would in the program.
TRANSPARENT_SUPERVISION = LockstepSupervision(
    max_message_age_s=1e12, resync_messages=1, sync_tolerance_m=1e12,
    work_area_m=(-math.inf, math.inf, -math.inf, math.inf),
    input_guard=InputGuardSettings(
        force_limit_N=math.inf, force_trip_N=math.inf, force_rate_limit_N_per_s=math.inf,
        position_min_m=(-math.inf, -math.inf), position_max_m=(math.inf, math.inf),
        velocity_trip_m_per_s=math.inf, jump_margin_m=math.inf, clear_after_messages=1))

TRACE_NAMES = ("handle_force_N", "handle_position_m", "tool_force_N", "tool_position_m",
               "tool_velocity_m_s", "tool_force_recv_N", "handle_command_m",
               "operator_intent_force_N")


class CombinedEnvironment:
    """The clay plus the linear impedance Tt: ft = clay force + Tt yt (docs/lockstep.md)."""

    kind = "clay+linear"

    def __init__(self, clay: Any, linear: LinearEnvironment) -> None:
        self.clay = clay
        self.linear = linear

    def initial_state(self, lanes: int = 1) -> Any:
        return self.clay.initial_state(lanes)

    def step(self, state: Any, previous_xy: np.ndarray, position_xy: np.ndarray,
             velocity_xy: np.ndarray, acceleration_xy: np.ndarray) -> ClayStepResult:
        cut = self.clay.step(state, previous_xy, position_xy, velocity_xy, acceleration_xy)
        spring = self.linear.step(None, previous_xy, position_xy, velocity_xy, acceleration_xy)
        return replace(cut, force_N=cut.force_N + spring.force_N)


@dataclass
class WindowStats:
    """Statistics per window of ``window_samples`` ticks, per lane and axis (windows, lanes,
    2): extremes, sums and sums of squares of the handle and tool forces over the
    window's samples (N, N, N^2)."""

    window_samples: int
    handle_force_max_N: np.ndarray
    handle_force_min_N: np.ndarray
    handle_force_sum_N: np.ndarray
    handle_force_sumsq_N2: np.ndarray
    handle_force_moment_N: np.ndarray  # sum of (sample index in the window) * fh
    tool_force_max_N: np.ndarray
    tool_force_min_N: np.ndarray
    tool_force_sum_N: np.ndarray
    tool_force_sumsq_N2: np.ndarray


@dataclass
class LockstepResult:
    """A run: window statistics for every lane, whole-run figures, optional full traces.

    ``peak_handle_force_N``/``peak_tool_force_N`` (lanes, 2): max |f| over the run;
    ``position_error_rms_m`` (lanes, 2): RMS of yh - yt (both at t_k);
    ``diverged`` (lanes,): a non-finite value appeared; ``traces``: name -> (steps, lanes
    recorded, 2) for the names in TRACE_NAMES, when recording was asked for.
    """

    sample_period_s: float
    steps: int
    gains_k: np.ndarray
    round_trip_delay_samples: np.ndarray
    stats: WindowStats
    peak_handle_force_N: np.ndarray
    peak_tool_force_N: np.ndarray
    position_error_rms_m: np.ndarray
    diverged: np.ndarray
    recorded_lanes: np.ndarray
    traces: dict[str, np.ndarray] = field(default_factory=dict)
    safety_events: int = 0
    governed: GovernedLanes | None = None
    #: (lanes, 2): RMS of fh - ft/Ah2, N (what the operator feels against what the tool
    #: applies, scaled), and yt - Ah1 yh at the last tick, m.
    force_error_rms_N: np.ndarray | None = None
    final_position_gap_m: np.ndarray | None = None

    @property
    def time_s(self) -> np.ndarray:
        """Sample instants t_k, s."""
        return np.arange(self.steps) * self.sample_period_s

    @property
    def simulated_seconds(self) -> float:
        """Simulated time summed over lanes, s."""
        return self.steps * self.sample_period_s * len(self.gains_k)


def concatenate_results(parts: Sequence[LockstepResult]) -> LockstepResult:
    """One result of the lanes of ``parts`` in order (runs of the same steps, period and
    windows over disjoint lanes, e.g. a sweep split over processes): every per-lane array
    joined along its lane axis, the safety events summed. Parts with recorded traces or
    governors are refused (their lanes index the part)."""
    if not parts:
        raise ValueError("concatenate_results needs at least one part")
    first = parts[0]
    if any(p.recorded_lanes.size or p.governed is not None for p in parts):
        raise ValueError("parts with recorded lanes or governors cannot be joined")
    if any((p.steps, p.sample_period_s, p.stats.window_samples)
           != (first.steps, first.sample_period_s, first.stats.window_samples) for p in parts):
        raise ValueError("parts must share steps, period and windows")

    def joined(name: str, axis: int = 0, source: Any = None) -> Any:
        values = [getattr(p if source is None else source(p), name) for p in parts]
        if any(value is None for value in values):
            return None
        return np.concatenate(values, axis=axis)

    stats = WindowStats(first.stats.window_samples, *(
        joined(f.name, 1, lambda p: p.stats) for f in fields(WindowStats)
        if f.name != "window_samples"))
    return LockstepResult(
        sample_period_s=first.sample_period_s, steps=first.steps, gains_k=joined("gains_k"),
        round_trip_delay_samples=joined("round_trip_delay_samples"), stats=stats,
        peak_handle_force_N=joined("peak_handle_force_N"),
        peak_tool_force_N=joined("peak_tool_force_N"),
        position_error_rms_m=joined("position_error_rms_m"), diverged=joined("diverged"),
        recorded_lanes=first.recorded_lanes.copy(),
        safety_events=sum(p.safety_events for p in parts),
        force_error_rms_N=joined("force_error_rms_N"),
        final_position_gap_m=joined("final_position_gap_m"))


def stacked_compensators(model: TeleopModel, gains_k: np.ndarray
                         ) -> tuple[DiscreteLTI | StackedLTI, DiscreteLTI | StackedLTI]:
    """Master and slave compensator blocks for per-lane gains: plain blocks when every
    lane has the same gain, stacked ones otherwise (one synthesis per distinct gain)."""
    distinct = np.unique(gains_k)
    masters, slaves = {}, {}
    for gain in distinct:
        gained = model.with_gain(float(gain))
        synthesized = synthesize(gained)  # once for both sides
        masters[gain] = master_compensator(gained, synthesized)
        slaves[gain] = slave_compensators(gained, synthesized)
    if distinct.size == 1:
        return masters[distinct[0]], slaves[distinct[0]]
    return (StackedLTI.from_blocks([masters[g] for g in gains_k]),
            StackedLTI.from_blocks([slaves[g] for g in gains_k]))


class LockstepSimulator:
    """Both nodes, the rig and the operator for ``gains_k`` (one gain per lane).

    ``environment``: "linear" (ft = Tt yt with the model's Tt), "clay" (the scenario's Warp
    clay) or "clay+linear" (their sum). ``safety``: the master's limits (default
    :data:`TRANSPARENT_SAFETY`). ``force_noise_std_N``: the rig's sensor noise.
    """

    def __init__(self, model: TeleopModel, scenario: Scenario, operator: OperatorModel,
                 gains_k: np.ndarray, environment: str = "linear",
                 safety: SafetySettings = TRANSPARENT_SAFETY, force_noise_std_N: float = 0.0,
                 clay_impl: str = "warp", device: str = "auto",
                 supervision: LockstepSupervision = TRANSPARENT_SUPERVISION,
                 passivity: PassivitySettings | None = None,
                 drift: DriftCoupling | None = None, passivity_standby: bool = False) -> None:
        if environment not in ENVIRONMENTS:
            raise ValueError(f"environment must be one of {', '.join(ENVIRONMENTS)}")
        self.model = model
        self.period_s = model.sample_period_s
        self.gains_k = np.atleast_1d(np.asarray(gains_k, float))
        self.lanes = self.gains_k.size
        self.environment = environment
        master_block, slave_block = stacked_compensators(model, self.gains_k)
        # passivity: None runs the paper's scheme, settings the TDPA layer (tdpa mode); with
        # passivity_standby the layer waits switched off for the governors' tdpa action (the
        # paper's scheme until a lane's governor switches it on, the slave following the flag)
        self.passivity = passivity
        self.passivity_standby = bool(passivity_standby and passivity is not None)
        # the work area both sides hold, as the programs do (common/model/work_area.py): the
        # handle's workspace and the slave's work area, the tighter bound of each for both
        self.work_area = shared_work_area(
            [a.position_ratio_ah1 for a in model.axes], safety.workspace_min_m,
            safety.workspace_max_m, supervision.work_area_m)
        self.master = MasterNode(master_block, with_work_area(safety, self.work_area),
                                 passivity, self.passivity_standby)
        self.rig = RigModel.from_model(model, operator, force_noise_std_N)
        base = "linear" if environment == "linear" else "clay"
        self.slave = SlaveNode(model, scenario, base, clay_impl, device, passivity, drift,
                               (self.work_area.tool_low_m, self.work_area.tool_high_m),
                               self.passivity_standby, slave_block)  # each lane its own k
        if environment == "clay+linear":
            self.slave.environment = CombinedEnvironment(
                make_environment("clay", model, scenario, clay_impl, device),
                LinearEnvironment(model))
        self.scenario = scenario
        self.supervision = supervision
        self.last_ticks: tuple[MasterTick, SlaveTick] | None = None
        #: the last run's quiet-lane filters (None: every lane supervised)
        self.last_quiet_lanes: tuple[MasterQuietLanes, SlaveQuietLanes] | None = None

    def ticks(self, handle_start_m: np.ndarray, tool_start_m: np.ndarray
              ) -> tuple[MasterTick, SlaveTick]:
        """The programs' two ticks (master/tick.py, slave_sim/tick.py) over every lane, one
        supervisor and input guard per lane, started in sync (the link up before tick 0)."""
        sup = self.supervision
        ratio = tuple(float(a.position_ratio_ah1) for a in self.model.axes)
        master = MasterTick(self.master, [
            MasterSupervisor(ratio, sup.sync_tolerance_m, sup.max_message_age_s,
                             sup.resync_messages) for _ in range(self.lanes)])
        master.start(handle_start_m, synced=True)
        slave_state = self.slave.initial_state(self.lanes, tool_start_m)
        slave = SlaveTick(self.slave, slave_state, [
            SlaveSupervisor(ratio, sup.sync_tolerance_m, sup.work_area_m, sup.max_message_age_s,
                            sup.resync_messages, grid_m=sup.grid_m)
            for _ in range(self.lanes)],
            [InputGuard(sup.input_guard, self.period_s) for _ in range(self.lanes)],
            ToolResync(self.slave))
        slave.handle_position_m[...] = handle_start_m
        slave.start(synced=True)
        return master, slave

    def run(self, duration_s: float, round_trip_delay_samples: np.ndarray | int, *,
            to_slave: InjectionConfig | None = None, to_master: InjectionConfig | None = None,
            seed: int = 0, excitation_N: np.ndarray | None = None, window_s: float = 0.25,
            record_lanes: np.ndarray | None = None,
            governors: Sequence[MarginGovernor] | None = None,
            every_lane_supervised: bool = False,
            schedules: tuple[np.ndarray, np.ndarray] | None = None) -> LockstepResult:
        """Run every lane for ``duration_s``.

        ``round_trip_delay_samples`` (scalar or (lanes,)): whole samples, split d1 = n // 2
        on the handle line and d2 = n - d1 on the tool line. ``to_slave``/``to_master``:
        injected delay, jitter and loss on each line (as the link's receiving side).
        ``excitation_N``: (steps, 2) added to the operator's intent (a test pulse).
        ``record_lanes``: lanes whose full traces are kept (default none).
        ``governors``: one margin governor per lane (lockstep/governed.py): k follows it on
        both sides; the result's ``governed`` holds the gains used and the events.
        ``every_lane_supervised``: feed every lane's message object to its supervisor and
        guard each tick, as the program does, instead of letting the lanes with nothing to
        change only store their messages (lockstep/quiet_lanes.py; the same run, bit for bit,
        several times slower: tests/lockstep/test_quiet_lanes.py).
        ``schedules``: the handle and tool lines' source schedules (steps, lanes) to use
        instead of drawing them (:func:`line_schedules` of the same arguments gives the ones
        drawn here): a sweep split over processes draws them once for every lane and hands
        each part its columns, so the split run is the whole run, bit for bit.
        """
        ts = self.period_s
        steps = int(round(duration_s / ts))
        lanes = self.lanes
        delays = np.broadcast_to(np.asarray(round_trip_delay_samples, np.int64), (lanes,))
        if schedules is None:
            schedules = line_schedules(steps, ts, delays, to_slave, to_master, seed)
        elif any(np.shape(schedule) != (steps, lanes) for schedule in schedules):
            raise ValueError(f"schedules must be two ({steps}, {lanes}) arrays")
        governed = None if governors is None else GovernedLanes(governors, self.gains_k, steps)
        run = self._start_run(delays, schedules, np.random.default_rng(seed).spawn(3)[2],
                              governed, every_lane_supervised)
        run.excitation_N = None if excitation_N is None else np.asarray(excitation_N, float)
        run.tally = _WindowTally(steps, max(1, int(round(window_s / ts))), lanes,
                                 np.array([a.force_ratio_ah2 for a in self.model.axes]))
        run.recorded = np.asarray([] if record_lanes is None else record_lanes, int)
        run.traces = {name: np.empty((steps, run.recorded.size, 2)) for name in TRACE_NAMES} \
            if run.recorded.size else {}
        # the heap from before the run is frozen: a full collection in the middle of the run
        # (the set-up leaves enough young survivors to start one) would rescan every object
        # the program holds, Warp's and the analysis' included, for no garbage
        with np.errstate(over="ignore", invalid="ignore"), frozen_heap(collect=False):
            for k in range(steps):
                self._master_step(run, k)
                self._slave_step(run, k)
        return self._finish_run(run, delays)

    def _start_run(self, delays: np.ndarray, schedules: tuple[np.ndarray, np.ndarray],
                   rig_rng: np.random.Generator, governed: GovernedLanes | None,
                   every_lane_supervised: bool) -> _Run:
        """A run's ticks (in sync), lines (holding the run-up's messages) and rig, lanes
        at the scenario's start; the quiet-lane filters unless ``every_lane_supervised``."""
        lanes, ts = self.lanes, self.period_s
        tdpa = self.passivity is not None  # the messages carry the cumulative input energy
        start = np.broadcast_to(np.asarray(self.scenario.tool.start_position_m, float),
                                (lanes, 2))
        ratio = np.array([a.position_ratio_ah1 for a in self.model.axes])
        handle_start = start / ratio
        master_tick, slave_tick = self.ticks(handle_start, start)
        self.last_ticks = (master_tick, slave_tick)  # the run's ticks, for inspection
        # the messages before tick 0 (the link runs in sync before the run): no force, the
        # handle and the tool at their start, forces enabled on both sides; each line's
        # receive also gives the arrivals: the run-up's messages were sent the line's delay
        # (plus its structural sample) before they are read
        enabled = float(Flags.FORCES_ENABLED)
        initial = np.zeros((lanes, HandleMessages.channels(governed is not None, tdpa)))
        handle_runup = HandleMessages(initial, governed is not None, tdpa)
        handle_runup.position_m[...] = handle_start
        handle_runup.flags[...] = enabled
        handle_runup.force_scale[...] = master_tick.state.force_scale
        if handle_runup.gain_ratio is not None:
            handle_runup.gain_ratio[...] = 1.0
        to_slave_d = delays // 2
        handles = handle_line(schedules[0], initial, ts, to_slave_d, governed is not None, tdpa)
        initial = np.zeros((lanes, ToolMessages.channels(tdpa)))
        tool_runup = ToolMessages(initial, tdpa)
        tool_runup.position_m[...] = start
        tool_runup.flags[...] = enabled
        tools = tool_line(schedules[1], initial, ts, delays - to_slave_d + 1, tdpa)
        if governed is not None:
            slave_tick.follow_gain_ratio(handle_runup.gain_ratio)
        quiet = None if every_lane_supervised else (MasterQuietLanes(master_tick, tools),
                                                     SlaveQuietLanes(slave_tick, handles))
        self.last_quiet_lanes = quiet
        return _Run(master_tick, slave_tick, handles, tools, quiet,
                    self.rig.initial_state(handle_start, rig_rng),
                    master_tick.state.last_command_m.copy(), ratio, governed, tdpa)

    def _master_step(self, run: _Run, k: int) -> None:
        """Tick ``k`` of the master: read (the rig at SYNC k) -> poll -> supervise -> node ->
        write/send (the handle line's message sent at k, written in place)."""
        now_s = k * self.period_s
        master_tick = run.master_tick
        tool = run.tools.receive(k)
        sample = self.rig.step(run.rig_state, run.command, tool.force_N)
        fh = sample.handle_force_measured_N
        if run.excitation_N is not None and k < run.excitation_N.shape[0]:
            fh = fh + run.excitation_N[k]
        yh = sample.handle_position_m
        if run.quiet is None:
            master_tick.supervise(now_s, run.tools.messages(), yh,
                                  silence_s=run.tools.silence_s.tolist())
        else:
            run.quiet[0].supervise(now_s, yh)
        sent = run.handles.slot(k)
        governed = run.governed
        gain_ratio = None
        if governed is not None:  # k on the master now, on the slave with the message
            gain_ratio = governed.update(k, self.period_s, run.tools.schedule,
                                         run.handles.schedule)
            sent.gain_ratio[...] = gain_ratio
            if self.passivity_standby and governed.switches:  # the tdpa action
                for mask, on in ((governed.switch_on, True), (governed.switch_off, False)):
                    if mask.any():
                        master_tick.switch_passivity(now_s, mask, on, "governor")
        # the node's inputs from the slave (its energy and tool: the line's newest message,
        # None in the paper's mode) and the governor, as the program's lane gives them
        used = master_tick.control(fh, yh, None, tool.energy_J, tool.position_m, gain_ratio)
        # a view the master's next control overwrites: the rig reads it before then
        run.command = used.command_m
        sent.force_N[...] = used.handle_force_used_N
        sent.position_m[...] = yh
        sent.flags[...] = used.flag_values
        sent.force_scale[...] = used.force_scale
        if run.tdpa:
            sent.energy_J[...] = master_tick.state.passivity.sent_J
        run.handle_force_N, run.handle_position_m = fh, yh
        run.rig_sample, run.tool_force_recv_N = sample, tool.force_N

    def _slave_step(self, run: _Run, k: int) -> None:
        """Tick ``k`` of the slave: poll -> supervise -> node -> send (the tool line's message
        sent at k, written in place); then the tick's statistics and traces."""
        now_s = k * self.period_s
        slave_tick = run.slave_tick
        received = run.handles.receive(k)
        run.tally.add_tool_position(k, slave_tick.state.tool[:, 0::2])  # t_k, before the step
        if run.quiet is None:
            slave_tick.supervise(now_s, run.handles.messages(),
                                 silence_s=run.handles.silence_s.tolist())
        else:
            run.quiet[1].supervise(now_s)
        if run.governed is not None:
            slave_tick.follow_gain_ratio(received.gain_ratio)
        if run.tdpa:  # the master's handed-over energy, as the program's lane takes it
            slave_tick.receive_peer_energy(received.energy_J)
        ticked = slave_tick.control()
        out = ticked.out
        ft = out.tool_force_N
        sent = run.tools.slot(k)
        sent.force_N[...] = ft
        sent.position_m[...] = out.tool_position_m
        sent.velocity_m_s[...] = out.tool_velocity_m_s
        sent.flags[...] = ticked.flag_values
        if run.tdpa:
            sent.energy_J[...] = slave_tick.state.passivity.sent_J
        fh, yh = run.handle_force_N, run.handle_position_m
        run.tally.add(k, fh, ft, yh)
        recorded = run.recorded
        if recorded.size:
            values = (fh, yh, ft, out.tool_position_m, out.tool_velocity_m_s,
                      run.tool_force_recv_N, run.command, run.rig_sample.operator_intent_force_N)
            for name, value in zip(TRACE_NAMES, values, strict=True):
                run.traces[name][k] = value[recorded]

    def _finish_run(self, run: _Run, delays: np.ndarray) -> LockstepResult:
        """The run's result, with every supervisor and guard told what its quiet lanes
        took."""
        if run.quiet is not None:
            for quiet in run.quiet:
                quiet.sync()
        master_state, slave_state = run.master_tick.state, run.slave_tick.state
        self.final_states = (master_state, slave_state)
        tally = run.tally
        stats = tally.stats
        steps = tally.steps
        finite = np.isfinite(stats.handle_force_sumsq_N2).all(axis=(0, 2)) & np.isfinite(
            stats.tool_force_sumsq_N2).all(axis=(0, 2))
        return LockstepResult(
            sample_period_s=self.period_s, steps=steps, gains_k=self.gains_k.copy(),
            round_trip_delay_samples=np.array(delays), stats=stats,
            peak_handle_force_N=tally.peak_handle_force_N,
            peak_tool_force_N=tally.peak_tool_force_N,
            position_error_rms_m=np.sqrt(tally.position_error_sumsq_m2 / max(steps, 1)),
            diverged=~finite | master_state.faulted, recorded_lanes=run.recorded,
            traces=run.traces, safety_events=len(run.master_tick.take_node_events()),
            governed=run.governed,
            force_error_rms_N=np.sqrt(tally.force_error_sumsq_N2 / max(steps, 1)),
            final_position_gap_m=(slave_state.tool[:, [0, 2]] - run.ratio * run.handle_position_m)
            if steps else np.zeros((self.lanes, 2)),
        )


@dataclass(eq=False)
class _Run:
    """What one :meth:`LockstepSimulator.run` steps: the two ticks, the lines, the quiet-lane
    filters (None: every lane supervised), the rig, and what the master's half of a tick
    hands the slave's half (the handle's force and position, the rig's sample, the tool force
    received, the command)."""

    master_tick: MasterTick
    slave_tick: SlaveTick
    handles: HandleLine
    tools: ToolLine
    quiet: tuple[MasterQuietLanes, SlaveQuietLanes] | None
    rig_state: Any
    command: np.ndarray  # (lanes, 2), m: the handle command the rig applies next
    ratio: np.ndarray  # (2,) Ah1
    governed: GovernedLanes | None
    tdpa: bool
    excitation_N: np.ndarray | None = None
    tally: _WindowTally | None = None
    recorded: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    traces: dict[str, np.ndarray] = field(default_factory=dict)
    handle_force_N: np.ndarray | None = None
    handle_position_m: np.ndarray | None = None
    rig_sample: Any = None
    tool_force_recv_N: np.ndarray | None = None


def line_schedules(steps: int, period_s: float, round_trip_delay_samples: np.ndarray,
                   to_slave: InjectionConfig | None, to_master: InjectionConfig | None,
                   seed: int) -> tuple[np.ndarray, np.ndarray]:
    """The handle and tool lines' source schedules (steps, lanes) of a run
    (:meth:`LockstepSimulator.run`'s delays split d1 = n // 2, d2 = n - d1, its injections and
    seed): the handle line's from the seed's first spawned generator, the tool line's from
    its second (the third is the rig's)."""
    delays = np.atleast_1d(np.asarray(round_trip_delay_samples, np.int64))
    to_slave_d = delays // 2
    handle_rng, tool_rng, _ = np.random.default_rng(seed).spawn(3)
    return (source_schedule(steps, to_slave_d, 0, period_s, to_slave, handle_rng),
            source_schedule(steps, delays - to_slave_d, 1, period_s, to_master, tool_rng))


class _WindowTally:
    """The run's statistics (:class:`WindowStats`, the peaks and the sums of squared errors)
    from the ticks' forces and positions: each tick's values are copied into a buffer of one
    window, which is reduced when the window is full (a few whole-window numpy calls instead
    of some twenty per tick). Axis-0 reductions add the rows in tick order, so the sums are
    bit for bit those of a running sum per tick.

    ``force_ratio`` (2,): the model's Ah2 per axis (the force error is fh - ft / Ah2)."""

    def __init__(self, steps: int, window: int, lanes: int, force_ratio: np.ndarray) -> None:
        self.steps = steps
        self.window = window
        self.force_ratio = force_ratio
        n_windows = -(-steps // window)
        shape = (n_windows, lanes, 2)
        self.stats = WindowStats(window, np.full(shape, -np.inf), np.full(shape, np.inf),
                                 np.zeros(shape), np.zeros(shape), np.zeros(shape),
                                 np.full(shape, -np.inf), np.full(shape, np.inf),
                                 np.zeros(shape), np.zeros(shape))
        self.peak_handle_force_N = np.zeros((lanes, 2))
        self.peak_tool_force_N = np.zeros((lanes, 2))
        self.position_error_sumsq_m2 = np.zeros((lanes, 2))
        self.force_error_sumsq_N2 = np.zeros((lanes, 2))
        buffer = (window, lanes, 2)
        self._handle_force_N = np.empty(buffer)
        self._tool_force_N = np.empty(buffer)
        self._handle_position_m = np.empty(buffer)
        self._tool_position_m = np.empty(buffer)
        # row 0: the running sum, rows 1..: the window's terms (one reduction in tick order)
        self._terms = np.empty((window + 1, lanes, 2))
        self._sample_index = np.arange(window, dtype=float)[:, None, None]

    def add_tool_position(self, tick: int, tool_position_m: np.ndarray) -> None:
        """The tool's position at t_k (lanes, 2), m (before the slave's step)."""
        self._tool_position_m[tick % self.window] = tool_position_m

    def add(self, tick: int, handle_force_N: np.ndarray, tool_force_N: np.ndarray,
            handle_position_m: np.ndarray) -> None:
        """The tick's handle force and position (N, m) and the tool force it sent (N), each
        (lanes, 2); reduces the window after its last tick (or the run's)."""
        row = tick % self.window
        self._handle_force_N[row] = handle_force_N
        self._tool_force_N[row] = tool_force_N
        self._handle_position_m[row] = handle_position_m
        if row == self.window - 1 or tick == self.steps - 1:
            self._reduce(tick // self.window, row + 1)

    def _running_sum(self, total: np.ndarray, terms: np.ndarray) -> None:
        """``total`` += every row of ``terms``, in order, in place."""
        rows = terms.shape[0]
        self._terms[0] = total
        self._terms[1:rows + 1] = terms
        np.add.reduce(self._terms[:rows + 1], axis=0, out=total)

    def _reduce(self, w: int, rows: int) -> None:
        stats = self.stats
        fh, ft = self._handle_force_N[:rows], self._tool_force_N[:rows]
        for force, high, low, total, squares, peak in (
                (fh, stats.handle_force_max_N, stats.handle_force_min_N,
                 stats.handle_force_sum_N, stats.handle_force_sumsq_N2,
                 self.peak_handle_force_N),
                (ft, stats.tool_force_max_N, stats.tool_force_min_N, stats.tool_force_sum_N,
                 stats.tool_force_sumsq_N2, self.peak_tool_force_N)):
            np.maximum.reduce(force, axis=0, out=high[w])
            np.minimum.reduce(force, axis=0, out=low[w])
            np.add.reduce(force, axis=0, out=total[w])
            np.add.reduce(force * force, axis=0, out=squares[w])
            np.maximum(peak, np.maximum.reduce(np.abs(force), axis=0), out=peak)
        np.add.reduce(self._sample_index[:rows] * fh, axis=0, out=stats.handle_force_moment_N[w])
        error = self._handle_position_m[:rows] - self._tool_position_m[:rows]
        self._running_sum(self.position_error_sumsq_m2, error * error)
        force_error = fh - ft / self.force_ratio
        self._running_sum(self.force_error_sumsq_N2, force_error * force_error)
