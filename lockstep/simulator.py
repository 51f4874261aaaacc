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
``sample_period_s`` = Ts at tau = n Ts, and the loop :mod:`haptic.common.linear_loop`
simulates (with the linear environment and the safety layer out of the way).

Lanes may differ in the Ch1 gain k (the compensators are stacked per lane) and in their
delays; everything random comes from one seeded generator, so a run is bit-for-bit
reproducible.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from haptic.common.config.scenario import Scenario
from haptic.common.drift import DriftCoupling
from haptic.common.injection import InjectionConfig
from haptic.common.lti import DiscreteLTI
from haptic.common.model import TeleopModel
from haptic.common.passivity import PassivitySettings
from haptic.lockstep.delay_line import DelayLine, source_schedule
from haptic.lockstep.stacked import StackedLTI
from haptic.master.node import MasterNode, master_compensator
from haptic.master.operator import OperatorModel
from haptic.master.rig_model import RigModel
from haptic.master.settings import SafetySettings
from haptic.slave_sim.clay import ClayStepResult
from haptic.slave_sim.environment import LinearEnvironment, make_environment
from haptic.slave_sim.node import SlaveNode, slave_compensators

ENVIRONMENTS = ("linear", "clay", "clay+linear")

#: Safety settings that never act on a sweep's signals: the lockstep compares the loop with
#: the analysis, which has no saturation, ramp or trip (docs/lockstep.md).
TRANSPARENT_SAFETY = SafetySettings(
    force_limit_N=1e12, force_trip_N=1e15, velocity_limit_m_per_s=1e12,
    velocity_trip_m_per_s=1e15, workspace_min_m=(-1e12, -1e12), workspace_max_m=(1e12, 1e12),
    workspace_trip_margin_m=1e12, ramp_small_force_N=1e14, ramp_small_samples=1,
    ramp_time_s=0.0,
)

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


def stacked_compensators(model: TeleopModel, gains_k: np.ndarray
                         ) -> tuple[DiscreteLTI | StackedLTI, DiscreteLTI | StackedLTI]:
    """Master and slave compensator blocks for per-lane gains: plain blocks when every
    lane has the same gain, stacked ones otherwise (one synthesis per distinct gain)."""
    distinct = np.unique(gains_k)
    masters, slaves = {}, {}
    for gain in distinct:
        gained = model.with_gain(float(gain))
        masters[gain], slaves[gain] = master_compensator(gained), slave_compensators(gained)
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
                 passivity: PassivitySettings | None = None,
                 drift: DriftCoupling | None = None) -> None:
        if environment not in ENVIRONMENTS:
            raise ValueError(f"environment must be one of {', '.join(ENVIRONMENTS)}")
        self.model = model
        self.period_s = model.sample_period_s
        self.gains_k = np.atleast_1d(np.asarray(gains_k, float))
        self.lanes = self.gains_k.size
        self.environment = environment
        master_block, slave_block = stacked_compensators(model, self.gains_k)
        # passivity: None runs the paper's scheme, settings the TDPA layer (tdpa mode).
        self.passivity = passivity
        self.master = MasterNode(master_block, safety, passivity)
        self.rig = RigModel.from_model(model, operator, force_noise_std_N)
        base = "linear" if environment == "linear" else "clay"
        self.slave = SlaveNode(model, scenario, base, clay_impl, device, passivity, drift)
        # The node synthesizes its compensators for the model's k; lanes use their own k.
        self.slave.compensators = slave_block
        if environment == "clay+linear":
            self.slave.environment = CombinedEnvironment(
                make_environment("clay", model, scenario, clay_impl, device),
                LinearEnvironment(model))
        self.scenario = scenario

    def run(self, duration_s: float, round_trip_delay_samples: np.ndarray | int, *,
            to_slave: InjectionConfig | None = None, to_master: InjectionConfig | None = None,
            seed: int = 0, excitation_N: np.ndarray | None = None, window_s: float = 0.25,
            record_lanes: np.ndarray | None = None) -> LockstepResult:
        """Run every lane for ``duration_s``.

        ``round_trip_delay_samples`` (scalar or (lanes,)): whole samples, split d1 = n // 2
        on the handle line and d2 = n - d1 on the tool line. ``to_slave``/``to_master``:
        injected delay, jitter and loss on each line (as the link's receiving side).
        ``excitation_N``: (steps, 2) added to the operator's intent (a test pulse).
        ``record_lanes``: lanes whose full traces are kept (default none).
        """
        ts = self.period_s
        steps = int(round(duration_s / ts))
        lanes = self.lanes
        delays = np.broadcast_to(np.asarray(round_trip_delay_samples, np.int64), (lanes,))
        rng = np.random.default_rng(seed)
        line_rngs = rng.spawn(3)
        to_slave_d = delays // 2
        tdpa = self.passivity is not None  # the messages carry the cumulative input energy
        handle_line = DelayLine(source_schedule(steps, to_slave_d, 0, ts, to_slave,
                                                line_rngs[0]), 4 + tdpa)
        tool_line = DelayLine(source_schedule(steps, delays - to_slave_d, 1, ts, to_master,
                                              line_rngs[1]), 2 + tdpa)
        start = np.broadcast_to(np.asarray(self.scenario.tool.start_position_m, float),
                                (lanes, 2))
        ratio = np.array([a.position_ratio_ah1 for a in self.model.axes])
        handle_start = start / ratio
        rig_state = self.rig.initial_state(handle_start, line_rngs[2])
        master_state = self.master.activate(handle_start)
        slave_state = self.slave.initial_state(lanes, start)
        command = master_state.last_command_m.copy()

        window = max(1, int(round(window_s / ts)))
        n_windows = -(-steps // window)
        shape = (n_windows, lanes, 2)
        stats = WindowStats(window, np.full(shape, -np.inf), np.full(shape, np.inf),
                            np.zeros(shape), np.zeros(shape), np.zeros(shape),
                            np.full(shape, -np.inf), np.full(shape, np.inf), np.zeros(shape),
                            np.zeros(shape))
        peak_fh = np.zeros((lanes, 2))
        peak_ft = np.zeros((lanes, 2))
        error_sumsq = np.zeros((lanes, 2))
        force_error_sumsq = np.zeros((lanes, 2))
        force_ratio = np.array([a.force_ratio_ah2 for a in self.model.axes])
        recorded = np.asarray([] if record_lanes is None else record_lanes, int)
        traces = {name: np.empty((steps, recorded.size, 2)) for name in TRACE_NAMES} \
            if recorded.size else {}
        excitation = None if excitation_N is None else np.asarray(excitation_N, float)

        with np.errstate(over="ignore", invalid="ignore"):
            for k in range(steps):
                ft_recv = tool_line.receive(k)
                slave_energy = ft_recv[:, 2] if tdpa else None
                ft_recv = ft_recv[:, :2]
                sample = self.rig.step(rig_state, command, ft_recv)
                fh = sample.handle_force_measured_N
                if excitation is not None and k < excitation.shape[0]:
                    fh = fh + excitation[k]
                yh = sample.handle_position_m
                command = self.master.step(master_state, fh, yh, ft_recv, slave_energy)
                handle_line.send(k, _message(tdpa, fh, yh, master_state.passivity))
                received = handle_line.receive(k)
                yt = slave_state.tool[:, [0, 2]]
                out = self.slave.step(slave_state, received[:, :2], received[:, 2:4],
                                      received[:, 4] if tdpa else None)
                ft = out.tool_force_N
                tool_line.send(k, _message(tdpa, ft, None, slave_state.passivity))

                w = k // window
                np.maximum(stats.handle_force_max_N[w], fh, out=stats.handle_force_max_N[w])
                np.minimum(stats.handle_force_min_N[w], fh, out=stats.handle_force_min_N[w])
                stats.handle_force_sum_N[w] += fh
                stats.handle_force_sumsq_N2[w] += fh * fh
                stats.handle_force_moment_N[w] += (k - w * window) * fh
                np.maximum(stats.tool_force_max_N[w], ft, out=stats.tool_force_max_N[w])
                np.minimum(stats.tool_force_min_N[w], ft, out=stats.tool_force_min_N[w])
                stats.tool_force_sum_N[w] += ft
                stats.tool_force_sumsq_N2[w] += ft * ft
                np.maximum(peak_fh, np.abs(fh), out=peak_fh)
                np.maximum(peak_ft, np.abs(ft), out=peak_ft)
                error = yh - yt
                error_sumsq += error * error
                force_error = fh - ft / force_ratio
                force_error_sumsq += force_error * force_error
                if recorded.size:
                    values = (fh, yh, ft, out.tool_position_m, out.tool_velocity_m_s, ft_recv,
                              command, sample.operator_intent_force_N)
                    for name, value in zip(TRACE_NAMES, values, strict=True):
                        traces[name][k] = value[recorded]
        self.final_states = (master_state, slave_state)
        finite = np.isfinite(stats.handle_force_sumsq_N2).all(axis=(0, 2)) & np.isfinite(
            stats.tool_force_sumsq_N2).all(axis=(0, 2))
        return LockstepResult(
            sample_period_s=ts, steps=steps, gains_k=self.gains_k.copy(),
            round_trip_delay_samples=np.array(delays), stats=stats,
            peak_handle_force_N=peak_fh, peak_tool_force_N=peak_ft,
            position_error_rms_m=np.sqrt(error_sumsq / max(steps, 1)),
            diverged=~finite | master_state.faulted, recorded_lanes=recorded, traces=traces,
            safety_events=len(master_state.events),
            force_error_rms_N=np.sqrt(force_error_sumsq / max(steps, 1)),
            final_position_gap_m=(slave_state.tool[:, [0, 2]] - ratio * yh) if steps else
            np.zeros((lanes, 2)),
        )


def _message(tdpa: bool, first: np.ndarray, second: np.ndarray | None, port: Any
             ) -> np.ndarray:
    """A line's message per lane: the signals, and in ``tdpa`` mode the sender's cumulative
    handed-over energy (J) as the last column."""
    parts = [first] if second is None else [first, second]
    if tdpa:
        parts.append(port.sent_J[:, None])
    return np.concatenate(parts, axis=1) if len(parts) > 1 else first
