"""A few sweep cells over the real Zenoh link: the lockstep's rig and operator and the
programs' two ticks (supervisors, input guard and nodes as they ship), one lane, but the two
delay lines replaced by two :class:`~haptic.common.wire.link.Link` objects (master and slave side,
in this process, over TCP on loopback) with the delay injected by the links' receive paths.
The loop is paced in real time at Ts, since the injected delay is wall-clock time: the
programs' runner (common/runtime/runner.py) over the one tick driver
(common/runtime/tick_driver.py), with a side for each end (:class:`CellMasterStages`,
:class:`CellSlaveStages`) as the programs have theirs.

The effective round trip is measured, not assumed: each side records how many ticks old the
message it used was (the sender stamps one message per tick, its sequence number is the tick),
and the round trip in samples is ``mean lag to the slave + mean lag to the master - 1`` (the
1 is the structural sample of the tool line, docs/lockstep.md section 1). Over real Zenoh
the slave cannot read a handle message in the tick it was sent, so the real link adds at least
one sample to the injected delay: the analysis is evaluated at the measured round trip.

On a loaded machine the loop falls behind its wall-clock schedule and catches up with ticks
run back to back, and a wall-clock delay then spans more ticks: the measured round trip can
exceed the injected one by several samples.
:func:`run_cell_at` therefore aims a cell at a multiple of the margin by the round trip it
measures, re-running it with the injection corrected by the excess when it lands on the
wrong side of the band, and a cell whose measured round trip lies within the sweep's 10 %
band of the margin is reported in the band, not judged (as the lockstep sweep's cells).
"""

from __future__ import annotations

import math
import time
import uuid
from dataclasses import dataclass, replace

import numpy as np

from haptic.common.config.scenario import load_scenario
from haptic.common.model.teleop import TeleopModel
from haptic.common.runtime.runner import RealTimeRunner
from haptic.common.runtime.tick_driver import Stage, TickDriver
from haptic.common.wire.injection import InjectionConfig
from haptic.common.wire.link import Link
from haptic.common.wire.link_config import LinkConfig
from haptic.common.wire.messages import Message
from haptic.common.wire.ports import free_port as _free_port
from haptic.lockstep.simulator import LockstepSimulator
from haptic.lockstep.sweep import BAND, PULSE_FORCE_N, PULSE_SAMPLES, analytic_margin_s
from haptic.master.simulated_rig.operator import parse_operator_spec
from haptic.master.simulated_rig.rig_block import RigModel, RigState
from haptic.master.tick import MasterLaneInputs, MasterTick
from haptic.slave_sim.tick import SlaveLaneInputs, SlaveTick

#: Sleep until this long before a tick's deadline, then spin (docs/link.md's pacing).
SPIN_S = 0.0003


@dataclass(frozen=True)
class RealLinkCell:
    """One cell run over Zenoh: the injected round trip, the measured one (s), the verdicts."""

    gain_k: float
    injected_round_trip_s: float
    measured_round_trip_s: float
    growing: bool
    analytic_stable: bool
    analytic_margin_s: float
    energy_ratio: float
    overruns: int
    steps: int
    attempts: int = 1
    #: the same lags in wall-clock time (s): from each used message's send to the poll that
    #: took it, both directions summed. Never below the injected round trip, however late
    #: the ticks ran; ``measured_round_trip_s`` counts ticks (what the loop's stability
    #: depends on), which late ticks move either way (docs/lockstep.md section 7).
    wall_round_trip_s: float = math.nan

    @property
    def agree(self) -> bool:
        """The lockstep's verdict matches the analysis at the measured round trip."""
        return self.growing != self.analytic_stable

    @property
    def in_band(self) -> bool:
        """The measured round trip lies within the sweep's band (10 %) of the margin."""
        return abs(self.measured_round_trip_s - self.analytic_margin_s) <= (
            BAND * self.analytic_margin_s)

    @property
    def disagrees_outside_band(self) -> bool:
        """A disagreement the check fails on: outside the band of the analytic boundary."""
        return not self.agree and not self.in_band


def _configs(one_way_s: tuple[float, float]) -> tuple[LinkConfig, LinkConfig]:
    endpoint = f"tcp/127.0.0.1:{_free_port()}"
    prefix = f"haptic-sim/{uuid.uuid4().hex[:10]}"
    common = {"key_prefix": prefix, "congestion_control": "block", "stale_after_s": 10.0}
    master = LinkConfig(side="master", listen=(endpoint,),
                        injection=InjectionConfig(delay_s=one_way_s[1]), **common)
    slave = LinkConfig(side="slave", connect=(endpoint,),
                       injection=InjectionConfig(delay_s=one_way_s[0]), **common)
    return master, slave


def _energy_ratio(force: np.ndarray, window: int, reference: int) -> float:
    """The verdict's detrended energy ratio (verdict.py) from a full trace (steps, 2)."""
    def detrended_variance(segment: np.ndarray) -> np.ndarray:
        index = np.arange(segment.shape[0])
        fit = np.polyfit(index, segment, 1)
        return np.var(segment - (np.outer(index, fit[0]) + fit[1]), axis=0)

    first = detrended_variance(force[reference * window:(reference + 1) * window])
    last = detrended_variance(force[-window:])
    return float(np.max(np.sqrt(last / np.maximum(first, 1e-300))))


class CellRecord:
    """What a cell keeps of each tick ``k`` of ``steps``: the handle force (steps, 2), N,
    how many ticks old the message each side used was (NaN: none yet) and how old in
    wall-clock time, s, from its send to the poll that took it; the tick each side's first
    message was sent in is its sequence number's origin."""

    def __init__(self, steps: int) -> None:
        self.handle_force_N = np.empty((steps, 2))
        self.lag_to_slave = np.zeros(steps)
        self.lag_to_master = np.zeros(steps)
        self.wall_lag_to_slave_s = np.full(steps, np.nan)
        self.wall_lag_to_master_s = np.full(steps, np.nan)
        #: perf_counter_ns() at each side's send in tick k (0: not sent)
        self.handle_sent_ns = np.zeros(steps, np.int64)
        self.tool_sent_ns = np.zeros(steps, np.int64)
        #: the sequence number of each side's first message (sent in tick 0), None before
        self.first_handle_seq: int | None = None
        self.first_tool_seq: int | None = None

    def lag(self, tick: int, latest: Message | None, first_seq: int | None) -> float:
        """How many ticks old ``latest`` (the newest message received) is at ``tick``."""
        if latest is None or first_seq is None:
            return np.nan
        return tick - (latest.seq - first_seq)

    @staticmethod
    def wall_lag_s(tick: int, lag: float, sent_ns: np.ndarray, now_ns: int) -> float:
        """Seconds from the send of the message ``lag`` ticks old at ``tick`` (the peer's
        send times ``sent_ns``) to ``now_ns``; NaN where there is none."""
        if not np.isfinite(lag) or not 0 <= tick - int(lag) < sent_ns.size:
            return np.nan
        sent = int(sent_ns[tick - int(lag)])
        return (now_ns - sent) * 1e-9 if sent else np.nan


class CellMasterStages:
    """The cell's master side (one tick of the driver): ``poll`` (the newest tool message,
    its lag), ``read`` (the rig at SYNC k shown that tool force and the last command; the
    sweep's pulse from the first tick with forces on), the whole tick (master/tick.py),
    ``write`` (the command the rig takes next), ``send`` (the handle message) and
    ``telemetry`` (the handle force kept). The poll comes first: the rig shows the operator
    the newest tool force, as the lockstep's does."""

    stage_names = ("poll", "read", "supervise", "node", "write", "send", "telemetry")
    schedule_shift_ns = 0

    def __init__(self, link: Link, tick: MasterTick, rig: RigModel, rig_state: RigState,
                 gain_k: float, period_s: float, record: CellRecord) -> None:
        self.link = link
        self.tick = tick
        self.rig = rig
        self.rig_state = rig_state
        self.period_s = period_s
        self.record = record
        self.inputs = MasterLaneInputs()
        self.outputs = tick.configure_lane(gain_k)
        self.command_m = tick.state.last_command_m.copy()
        self.tool_force_N = np.zeros((1, 2))  # the newest received, held (as lockstep)
        #: the first tick with the master's forces on (None: not yet)
        self.enabled_at: int | None = None

    def stages(self) -> tuple[Stage, ...]:
        """poll, read, the whole tick, write, send, telemetry."""
        return (self.poll, self.read, self.step_tick, self.write, self.send, self.telemetry)

    def poll(self, tick: int, _now_ns: int) -> None:
        """The newest tool message and its lag."""
        link, inputs = self.link, self.inputs
        inputs.now_s = tick * self.period_s
        inputs.message = link.poll()
        latest = inputs.latest = link.latest
        inputs.silence_s = link.silence_s()
        inputs.peer_alive = link.peer_alive
        if latest is not None:
            self.tool_force_N = np.array([latest.tool_force_N])
        record = self.record
        lag = record.lag_to_master[tick] = record.lag(tick, latest, record.first_tool_seq)
        record.wall_lag_to_master_s[tick] = record.wall_lag_s(
            tick, lag, record.tool_sent_ns, time.perf_counter_ns())

    def read(self, tick: int, _now_ns: int) -> None:
        """The rig at SYNC k, and the sweep's pulse (the ticks enable forces once both
        sides have seen each other's messages over the link)."""
        sample = self.rig.step(self.rig_state, self.command_m, self.tool_force_N)
        force = sample.handle_force_measured_N
        if self.enabled_at is not None and tick - self.enabled_at < PULSE_SAMPLES:
            force = force + PULSE_FORCE_N
        self.inputs.handle_force_N = force
        self.inputs.handle_position_m = sample.handle_position_m

    def step_tick(self, tick: int, _now_ns: int) -> int:
        """The whole tick; returns the clock at its supervise | node boundary."""
        return self.tick.step_lane(self.inputs, time.perf_counter_ns).supervised_ns

    def write(self, tick: int, _now_ns: int) -> None:
        """The command the rig takes at the next SYNC."""
        used = self.outputs.used
        self.command_m = used.command_m.copy()
        if self.enabled_at is None and bool(used.enabled[0]):
            self.enabled_at = tick + 1

    def send(self, tick: int, _now_ns: int) -> None:
        """The handle message (the first one's sequence number is the lag's origin)."""
        outputs = self.outputs
        used = outputs.used
        sent = self.link.send_handle(tuple(used.handle_force_used_N[0].tolist()),
                                     tuple(self.inputs.handle_position_m[0].tolist()),
                                     outputs.flags, outputs.gain_k, outputs.energy_J,
                                     float(used.force_scale[0]))
        self.record.handle_sent_ns[tick] = time.perf_counter_ns()
        if self.record.first_handle_seq is None:
            self.record.first_handle_seq = sent.seq

    def telemetry(self, tick: int, _now_ns: int) -> None:
        """The handle force of this tick, for the verdict."""
        self.record.handle_force_N[tick] = self.inputs.handle_force_N[0]


class CellSlaveStages:
    """The cell's slave side: ``poll`` (the newest handle message, its lag), the whole tick
    (slave_sim/tick.py, one node step a tick), ``send`` (the tool message)."""

    stage_names = ("poll", "supervise", "node", "send")
    schedule_shift_ns = 0

    def __init__(self, link: Link, tick: SlaveTick, period_s: float,
                 record: CellRecord) -> None:
        self.link = link
        self.tick = tick
        self.period_s = period_s
        self.record = record
        self.inputs = SlaveLaneInputs()
        self.outputs = tick.configure_lane(None)

    def stages(self) -> tuple[Stage, ...]:
        """poll, the whole tick, send."""
        return (self.poll, self.step_tick, self.send)

    def poll(self, tick: int, _now_ns: int) -> None:
        """The newest handle message and its lag."""
        link, inputs = self.link, self.inputs
        inputs.now_s = tick * self.period_s
        inputs.message = link.poll()
        inputs.silence_s = link.silence_s()
        inputs.peer_alive = link.peer_alive
        record = self.record
        lag = record.lag_to_slave[tick] = record.lag(tick, link.latest,
                                                     record.first_handle_seq)
        record.wall_lag_to_slave_s[tick] = record.wall_lag_s(
            tick, lag, record.handle_sent_ns, time.perf_counter_ns())

    def step_tick(self, tick: int, _now_ns: int) -> int:
        """The whole tick; returns the clock at its supervise | node boundary."""
        return self.tick.step_lane(self.inputs, time.perf_counter_ns).supervised_ns

    def send(self, tick: int, _now_ns: int) -> None:
        """The tool message (the first one's sequence number is the lag's origin)."""
        outputs = self.outputs
        out = outputs.ticked.out
        sent = self.link.send_tool(tuple(out.tool_force_N[0].tolist()),
                                   tuple(out.tool_position_m[0].tolist()),
                                   tuple(out.tool_velocity_m_s[0].tolist()), 0.0, 0.0,
                                   outputs.flags, outputs.echo_send_time_ns, outputs.energy_J)
        self.record.tool_sent_ns[tick] = time.perf_counter_ns()
        if self.record.first_tool_seq is None:
            self.record.first_tool_seq = sent.seq


def _wait_for_each_other(master_link: Link, slave_link: Link, timeout_s: float = 10.0) -> None:
    """Poll both links until each sees the other; raises RuntimeError after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while not (master_link.peer_alive and slave_link.peer_alive):
        master_link.poll()
        slave_link.poll()
        if time.monotonic() > deadline:
            raise RuntimeError("the two links did not find each other")
        time.sleep(0.001)
    master_link.poll()
    slave_link.poll()


def run_cell(model: TeleopModel, gain_k: float, injected_round_trip_s: float,
             duration_s: float = 3.0, window_s: float = 0.25) -> RealLinkCell:
    """One cell over the real link (the linear loop, the sweep's pulse)."""
    ts = model.sample_period_s
    simulator = LockstepSimulator(model, load_scenario("constant-rate"),
                                  parse_operator_spec("constant:fx=0,fy=0"),
                                  np.array([gain_k]), "linear")
    rig = simulator.rig
    start = np.zeros((1, 2))
    rig_state = rig.initial_state(start, np.random.default_rng(0))
    # the programs' ticks (master/tick.py, slave_sim/tick.py: supervisors, input guard,
    # resync and nodes as they ship), started in sync as the lockstep's lanes are
    master_tick, slave_tick = simulator.ticks(start, start)
    steps = int(round(duration_s / ts))
    record = CellRecord(steps)
    half = injected_round_trip_s / 2.0
    master_cfg, slave_cfg = _configs((half, injected_round_trip_s - half))
    with Link(master_cfg) as master_link, Link(slave_cfg) as slave_link:
        _wait_for_each_other(master_link, slave_link)
        driver = TickDriver([
            CellMasterStages(master_link, master_tick, rig, rig_state, gain_k, ts, record),
            CellSlaveStages(slave_link, slave_tick, ts, record)])
        stats = RealTimeRunner(ts, driver.step, max_steps=steps, spin_s=SPIN_S,
                               show_status=False, handle_signals=False).run()
    settled = slice(steps // 4, None)
    measured = (np.nanmean(record.lag_to_slave[settled])
                + np.nanmean(record.lag_to_master[settled]) - 1.0) * ts
    wall = (np.nanmean(record.wall_lag_to_slave_s[settled])
            + np.nanmean(record.wall_lag_to_master_s[settled]))
    window = int(round(window_s / ts))
    handle_force = record.handle_force_N
    ratio = _energy_ratio(handle_force, window, 1)
    growing = (not np.all(np.isfinite(handle_force))) or ratio > 1.0
    margin = analytic_margin_s(model, gain_k, ts)
    return RealLinkCell(float(gain_k), injected_round_trip_s, float(measured), bool(growing),
                        bool(measured < margin), float(margin), ratio, stats.overruns, steps,
                        wall_round_trip_s=float(wall))


def run_cell_at(model: TeleopModel, gain_k: float, margin_factor: float,
                duration_s: float = 3.0, attempts: int = 3) -> RealLinkCell:
    """A cell aimed at ``margin_factor`` times the sampled margin, by its measured round trip.

    The first run injects the target round trip; while the measured one lands on the wrong
    side of the band (below 1 + BAND times the margin for a factor above 1, above 1 - BAND
    times it for one below), the cell is run again with the injection corrected by the
    excess it measured (never below 0 s), at most ``attempts`` runs in all. The last run is
    returned, with the number of runs it took.
    """
    if margin_factor <= 0.0 or abs(margin_factor - 1.0) <= BAND:
        raise ValueError("margin_factor must be positive and outside the band around 1")
    margin = analytic_margin_s(model, gain_k, model.sample_period_s)
    target_s = margin_factor * margin
    injected_s = target_s
    for attempt in range(1, attempts + 1):
        cell = run_cell(model, gain_k, injected_s, duration_s)
        measured = cell.measured_round_trip_s
        on_side = (measured < (1.0 - BAND) * margin if margin_factor < 1.0
                   else measured > (1.0 + BAND) * margin)
        if on_side or attempt == attempts:
            break
        injected_s = max(0.0, injected_s - (measured - target_s))
    return replace(cell, attempts=attempt)
