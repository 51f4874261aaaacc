"""A few sweep cells over the real Zenoh link: the lockstep's rig and operator and the
programs' two ticks (supervisors, input guard and nodes as they ship), one lane, but the two
delay lines replaced by two :class:`~haptic.common.wire.link.Link` objects (master and slave side,
in this process, over TCP on loopback) with the delay injected by the links' receive paths.
The loop is paced in real time at Ts, since the injected delay is wall-clock time.

The effective round trip is measured, not assumed: each side records how many ticks old the
message it used was (the sender stamps one message per tick, its sequence number is the tick),
and the round trip in samples is ``mean lag to the slave + mean lag to the master - 1`` (the
1 is the structural sample of the tool line, docs/lockstep.md section 1). Over real Zenoh
the slave cannot read a handle message in the tick it was sent, so the real link adds at least
one sample to the injected delay: the analysis is evaluated at the measured round trip.

On a loaded machine the loop falls behind its wall-clock schedule and catches up with ticks
run back to back, and a wall-clock delay then spans more ticks: the measured round trip can
exceed the injected one by several samples (1.8 ms on a busy CI machine at 28 % late ticks).
:func:`run_cell_at` therefore aims a cell at a multiple of the margin by the round trip it
measures, re-running it with the injection corrected by the excess when it lands on the
wrong side of the band, and a cell whose measured round trip lies within the sweep's 10 %
band of the margin is reported in the band, not judged (as the lockstep sweep's cells).
"""

from __future__ import annotations

import time
import uuid
from dataclasses import dataclass, replace

import numpy as np

from haptic.common.config.scenario import load_scenario
from haptic.common.model.teleop import TeleopModel
from haptic.common.wire.injection import InjectionConfig
from haptic.common.wire.link import Link
from haptic.common.wire.link_config import LinkConfig
from haptic.common.wire.ports import free_port as _free_port
from haptic.lockstep.simulator import LockstepSimulator
from haptic.lockstep.sweep import BAND, PULSE_FORCE_N, PULSE_SAMPLES, analytic_margin_s
from haptic.master.simulated_rig.operator import parse_operator_spec

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
    command = master_tick.state.last_command_m.copy()
    steps = int(round(duration_s / ts))
    handle_force = np.empty((steps, 2))
    lag_to_slave = np.zeros(steps)
    lag_to_master = np.zeros(steps)
    half = injected_round_trip_s / 2.0
    master_cfg, slave_cfg = _configs((half, injected_round_trip_s - half))
    overruns = 0
    with Link(master_cfg) as master_link, Link(slave_cfg) as slave_link:
        deadline = time.monotonic() + 10.0
        while not (master_link.peer_alive and slave_link.peer_alive):
            master_link.poll()
            slave_link.poll()
            if time.monotonic() > deadline:
                raise RuntimeError("the two links did not find each other")
            time.sleep(0.001)
        master_link.poll()
        slave_link.poll()
        first_seq = (master_link._seq, slave_link._seq)  # noqa: SLF001 - tick of seq 0
        tool_recv = np.zeros((1, 2))
        enabled_at: int | None = None  # the first tick with the master's forces on
        origin = time.perf_counter()
        for k in range(steps):
            tick_time = origin + k * ts
            now = time.perf_counter()
            if now > tick_time + ts:
                overruns += 1
            elif tick_time - now > SPIN_S:
                time.sleep(tick_time - now - SPIN_S)
            while time.perf_counter() < tick_time:
                pass
            now_s = k * ts
            # master: read (the rig) -> poll -> supervise -> node -> send
            message = master_link.poll()
            latest = master_link.latest
            if latest is not None:
                tool_recv = np.array([latest.tool_force_N])  # the newest, held (as lockstep)
                lag_to_master[k] = k - (latest.seq - first_seq[1])
            else:
                lag_to_master[k] = np.nan
            sample = rig.step(rig_state, command, tool_recv)
            fh = sample.handle_force_measured_N
            # the sweep's pulse, from the first tick with forces on (the ticks enable them
            # once both sides have seen each other's messages over the link)
            if enabled_at is not None and k - enabled_at < PULSE_SAMPLES:
                fh = fh + PULSE_FORCE_N
            yh = sample.handle_position_m
            master_tick.supervise(now_s, (message,), yh, silence_s=(master_link.silence_s(),))
            used = master_tick.control(fh, yh)
            command = used.command_m.copy()
            if enabled_at is None and bool(used.enabled[0]):
                enabled_at = k + 1
            master_link.send_handle(tuple(used.handle_force_used_N[0].tolist()),
                                    tuple(yh[0].tolist()), used.flags[0],
                                    force_scale=float(used.force_scale[0]))
            # slave: poll -> supervise -> node -> send
            message = slave_link.poll()
            latest = slave_link.latest
            if latest is not None:
                lag_to_slave[k] = k - (latest.seq - first_seq[0])
            else:
                lag_to_slave[k] = np.nan
            slave_tick.supervise(now_s, (message,), (slave_link.silence_s(),))
            ticked = slave_tick.control()
            out = ticked.out
            slave_link.send_tool(tuple(out.tool_force_N[0].tolist()),
                                 tuple(out.tool_position_m[0].tolist()),
                                 tuple(out.tool_velocity_m_s[0].tolist()), 0.0, 0.0,
                                 ticked.flags[0])
            handle_force[k] = fh[0]
    settled = slice(steps // 4, None)
    measured = (np.nanmean(lag_to_slave[settled]) + np.nanmean(lag_to_master[settled]) - 1.0) * ts
    window = int(round(window_s / ts))
    ratio = _energy_ratio(handle_force, window, 1)
    growing = (not np.all(np.isfinite(handle_force))) or ratio > 1.0
    margin = analytic_margin_s(model, gain_k, ts)
    return RealLinkCell(float(gain_k), injected_round_trip_s, float(measured), bool(growing),
                        bool(measured < margin), float(margin), ratio, overruns, steps)


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
