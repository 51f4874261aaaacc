"""The latency sweep: a grid of Ch1 gains k and round-trip delays run as lanes of one lockstep
simulation, each cell's time-domain verdict set against the sampled analysis of the same
loop (docs/lockstep.md).

Modes:

- ``linear`` (default): the analysis's own loop, operator impedance Th on the rig and the
  environment ft = Tt yt of the model (eq 33) on the slave, excited by a short operator
  force pulse; the time domain and the analysis compute the same system.
- ``clay``: the clay-cutting loop of the constant-rate scenario, the regulating operator
  cutting at 3.6 N; compared with the analysis of its linearisation about steady cutting,
  the clay's damper in series with the proxy's coupling (common/model/clay_contact.py).
"""

from __future__ import annotations

import math
import multiprocessing
import threading
import time
import traceback
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from haptic.common.analysis.report import AnalysisSettings, axis_loop
from haptic.common.analysis.stability import delay_margin
from haptic.common.config.scenario import load_scenario
from haptic.common.config.slave_schema import device_form_problem
from haptic.common.model.clay_contact import clay_impedance
from haptic.common.model.passivity import MODES as CONTROL_MODES
from haptic.common.model.passivity import PassivitySettings
from haptic.common.model.synthesis import SynthesisError
from haptic.common.model.teleop import TeleopModel
from haptic.common.runtime.machine import usable_cpu_count
from haptic.common.wire.injection import InjectionConfig
from haptic.lockstep.simulator import (
    LockstepResult,
    LockstepSimulator,
    concatenate_results,
    line_schedules,
)
from haptic.lockstep.verdict import GROWTH_THRESHOLD, growth_verdict
from haptic.master.simulated_rig.operator import parse_operator_spec
from haptic.slave_sim.clay.sim import device_problem as clay_device_problem
from haptic.slave_sim.clay.sim import resolve_device

MODES = ("linear", "clay")
#: The test pulse of the linear mode: 1 N on both axes for 20 samples (10.8 ms).
PULSE_FORCE_N = 1.0
PULSE_SAMPLES = 20
#: The clay mode's operator: a steady 3.6 N push brought in over 1 s. The analysis models
#: the operator as its arm's impedance Th with an exogenous intent; a regulating operator
#: (PI on the felt force) would add a loop the analysis does not have (docs/lockstep.md).
CLAY_OPERATOR = "constant:fx=3.6,fy=0,onset=0,rise=1.0"
#: The clay mode's verdict: an oscillation that does not decay to half its energy between the
#: reference window and the last one. The clay pushes only while it is cut, so a mode the
#: linearisation calls growing opens the contact and settles into a limit cycle (energy
#: ratio 0.8-1); a stable one decays (ratio below 0.05 outside the band).
CLAY_GROWTH_THRESHOLD = 0.5
#: Clay damping of the constant-rate workpiece used for the linearisation Tt = B s, N s/m.
CLAY_DAMPING_N_S_PER_M = 100.0
#: A linear-mode cell is bounded when no force exceeds this times the test pulse's.
BOUNDED_FORCE_FACTOR = 2.0
#: Mean length of a burst of lost messages in a bursty sweep, messages.
BURST_LENGTH_MESSAGES = 10.0
#: A disagreeing cell within this relative distance of the analytic boundary (in delay or
#: in gain) is inside the band.
BAND = 0.10


@dataclass(frozen=True)
class SweepSettings:
    """What a sweep runs (units in the names)."""

    gains_k: tuple[float, ...]
    delays_s: tuple[float, ...]
    mode: str = "linear"
    duration_s: float = 3.0
    window_s: float = 0.25
    reference_start_s: float = 0.25
    jitter_s: float = 0.0
    loss_probability: float = 0.0
    seed: int = 0
    #: "paper" (the paper's scheme) or "tdpa" (with the passivity layer, common/model/passivity.py).
    control: str = "paper"
    #: Loss in Gilbert-Elliott bursts of mean length BURST_LENGTH_MESSAGES at the same mean
    #: rate ``loss_probability``, instead of independent losses.
    bursty: bool = False
    #: Warp device of the clay lanes (clay mode): "cpu", "cuda", "cuda:N" or "auto" (CUDA
    #: where a device exists). The delay lines, compensators and rig run on the CPU in every
    #: mode. Workers are forked only for clay on the CPU: a forked child cannot use its
    #: parent's CUDA context, so a sweep whose clay is on CUDA runs its lanes in one process.
    device: str = "cpu"


#: The default grids, shared by ``haptic-sim sweep`` and bench/latency_sweep.py. The linear
#: loop's gains reach past k = 19's margin; the clay loop's margins are far shorter (k = 1.5:
#: about 22 ms, k = 2: 9 ms, k = 3: under 1 ms), so its grid stops at k = 1.5, where the
#: boundary still crosses the delays and no cell falls in the bistable region below k = 2's
#: margin (docs/lockstep.md, "The clay mode").
LINEAR_GAINS = (1.0, 3.0, 5.0, 8.0, 10.0, 13.0, 16.0, 19.0, 25.0, 30.0)
LINEAR_QUICK_GAINS = (1.0, 3.0, 8.0, 13.0, 19.0, 30.0)
CLAY_GAINS = (0.5, 0.75, 1.0, 1.25, 1.5)
#: Round-trip delays of the grids, s: 0 to 20 ms in 1 ms steps (quick: 2 ms).
DELAY_STEP_S = 0.001
QUICK_DELAY_STEP_S = 0.002
MAX_DELAY_S = 0.020
#: The clay sweep's run length, s: the last window must still cut the constant-rate block
#: (a fast, oscillating k = 3 lane leaves it at about 2.4 s).
CLAY_DURATION_S = 2.25


def delay_grid(step_s: float, max_s: float = MAX_DELAY_S) -> tuple[float, ...]:
    """Round-trip delays 0, step_s, ... up to ``max_s`` included, s."""
    count = int(math.floor(max_s / step_s + 1e-9)) + 1
    return tuple(step_s * i for i in range(count))


def default_settings(mode: str, quick: bool = False) -> SweepSettings:
    """The default grid of ``mode`` ("linear" or "clay"): gains, delays, run length and the
    reference window's start; ``quick`` is the CI-sized grid (fewer gains for the linear
    loop, 2 ms delay steps, linear runs of 2.5 s)."""
    delays = delay_grid(QUICK_DELAY_STEP_S if quick else DELAY_STEP_S)
    if mode == "clay":
        return SweepSettings(CLAY_GAINS, delays, "clay", CLAY_DURATION_S,
                             reference_start_s=1.0)
    if mode != "linear":
        raise ValueError(f"unknown sweep mode {mode!r}")
    if quick:
        return SweepSettings(LINEAR_QUICK_GAINS, delays, "linear", 2.5)
    return SweepSettings(LINEAR_GAINS, delays, "linear", 3.0)


@dataclass
class SweepResult:
    """Per cell (gain i, delay j): the lockstep and analytic verdicts and figures."""

    settings: SweepSettings
    sample_period_s: float
    delay_samples: np.ndarray  # (delays,) round trip in whole samples
    growing: np.ndarray  # (gains, delays) time-domain verdict
    analytic_stable: np.ndarray  # (gains, delays)
    in_band: np.ndarray  # (gains, delays) near the analytic boundary
    peak_force_N: np.ndarray  # (gains, delays) max |fh| over the axes
    position_error_rms_m: np.ndarray  # (gains, delays) worst axis
    amplitude_ratio: np.ndarray
    energy_ratio: np.ndarray
    margin_s: np.ndarray  # (gains,) analytic delay margin, inf: none, 0: unstable at 0
    simulated_seconds: float
    wall_seconds: float
    extra: dict = field(default_factory=dict)
    #: (gains, delays) max |fh| and |ft| over the axes and the run, N (None: not computed).
    max_abs_force_N: np.ndarray | None = None

    @property
    def bounded(self) -> np.ndarray:
        """Cells whose response stays bounded: finite, and in the linear mode no force above
        BOUNDED_FORCE_FACTOR times the test pulse over the run (a passivity layer may leave
        a small bounded chatter that the energy verdict, made for a decaying linear loop,
        would call growing); in the clay mode, not growing by the energy verdict."""
        peak = self.peak_force_N if self.max_abs_force_N is None else self.max_abs_force_N
        finite = np.isfinite(peak)
        if self.settings.mode != "linear":
            return finite & ~self.growing
        return finite & (peak <= BOUNDED_FORCE_FACTOR * PULSE_FORCE_N)

    @property
    def agree(self) -> np.ndarray:
        """Cells where the lockstep and the analysis give the same verdict."""
        return self.growing == ~self.analytic_stable

    def summary(self) -> dict:
        """The JSON figures of the sweep (cells, agreement, speed)."""
        agree = self.agree
        outside = ~agree & ~self.in_band
        bounded = int(self.bounded.sum())
        return {
            "mode": self.settings.mode,
            "control": self.settings.control,
            "cells": int(agree.size),
            "bounded": bounded,
            "unbounded": int(agree.size) - bounded,
            "agree": int(agree.sum()),
            "disagree": int((~agree).sum()),
            "disagree_outside_band": int(outside.sum()),
            "simulated_seconds": round(self.simulated_seconds, 3),
            "wall_seconds": round(self.wall_seconds, 3),
            "sim_per_wall": round(self.simulated_seconds / max(self.wall_seconds, 1e-9), 1),
            "workers": int(self.extra.get("workers", 1)),
            "device": str(self.extra.get("device", "cpu")),
        }

    def rows(self) -> list[dict]:
        """One dict per cell (the CSV rows)."""
        rows = []
        ts = self.sample_period_s
        for i, gain in enumerate(self.settings.gains_k):
            for j, samples in enumerate(self.delay_samples):
                rows.append({
                    "k": gain, "round_trip_delay_s": round(float(samples) * ts, 9),
                    "delay_samples": int(samples),
                    "lockstep": "growing" if self.growing[i, j] else "bounded",
                    "analysis": "stable" if self.analytic_stable[i, j] else "unstable",
                    "agree": bool(self.agree[i, j]), "in_band": bool(self.in_band[i, j]),
                    "analytic_margin_s": float(self.margin_s[i]),
                    "peak_force_N": float(self.peak_force_N[i, j]),
                    "position_error_rms_m": float(self.position_error_rms_m[i, j]),
                    "amplitude_ratio": float(self.amplitude_ratio[i, j]),
                    "energy_ratio": float(self.energy_ratio[i, j]),
                })
        return rows


def sweep_injection(settings: SweepSettings) -> InjectionConfig | None:
    """The injection on both lines of a sweep: independent losses, or Gilbert-Elliott bursts
    of mean length BURST_LENGTH_MESSAGES whose stationary loss rate is ``loss_probability``."""
    loss = settings.loss_probability
    if settings.jitter_s <= 0.0 and loss <= 0.0:
        return None
    if not settings.bursty or loss <= 0.0:
        return InjectionConfig(jitter_s=settings.jitter_s, loss_probability=loss)
    leave = 1.0 / BURST_LENGTH_MESSAGES
    return InjectionConfig(jitter_s=settings.jitter_s, burst_exit_probability=leave,
                           burst_enter_probability=min(1.0, loss * leave / (1.0 - loss)),
                           burst_loss_probability=1.0)


def per_cell(result: SweepResult, lockstep: Any) -> list[dict]:
    """One dict per cell: its control, delay, jitter and loss, and whether it stayed bounded,
    with its peak force, force and position errors and final position gap (units in the
    names)."""
    settings = result.settings
    gains = np.asarray(settings.gains_k, float)
    shape = (gains.size, result.delay_samples.size)
    force_error = lockstep.force_error_rms_N.max(axis=1).reshape(shape)
    gap = np.linalg.norm(lockstep.final_position_gap_m, axis=1).reshape(shape)
    peak = result.max_abs_force_N
    cells = []
    for i, gain in enumerate(gains):
        for j, samples in enumerate(result.delay_samples):
            cells.append({
                "control": settings.control,
                "round_trip_s": round(float(samples) * result.sample_period_s, 9),
                "jitter_s": settings.jitter_s, "loss": settings.loss_probability,
                "bursty": settings.bursty, "k": float(gain),
                "bounded": bool(result.bounded[i, j]),
                "max_abs_force_N": _finite(peak[i, j]),
                "rms_force_error_N": _finite(force_error[i, j]),
                "rms_position_error_m": _finite(result.position_error_rms_m[i, j]),
                "final_position_gap_m": _finite(gap[i, j]),
            })
    return cells


def _finite(value: float) -> float | None:
    """A JSON-safe number: None for inf/nan (a diverged lane)."""
    value = float(value)
    return value if np.isfinite(value) else None


def sweep_model(model: TeleopModel, mode: str) -> TeleopModel:
    """The model the analysis uses for ``mode``: as configured (linear) or with the clay
    linearised about steady cutting on both axes (clay: Tt = B s (K + b s) / (K + (B + b) s),
    common/model/clay_contact.py)."""
    if mode == "linear":
        return model
    if mode == "clay":
        num, den = clay_impedance(CLAY_DAMPING_N_S_PER_M)
        axes = tuple(axis.with_environment(num, den) for axis in model.axes)
        return TeleopModel(model.sample_period_s, model.ch1_gain_k, model.ch1_num,
                           model.ch1_den, axes)
    raise ValueError(f"mode must be one of {', '.join(MODES)} (got {mode!r})")


def analytic_margin_s(model: TeleopModel, gain_k: float, sample_period_s: float) -> float:
    """The sampled analysis's round-trip delay margin, worst axis, s: inf when no delay up
    to 1 s destabilises the loop, 0 when it is unstable without delay."""
    settings = AnalysisSettings(sample_period_s=sample_period_s)
    margin = np.inf
    for axis in model.axes:
        try:
            result = delay_margin(axis_loop(model, axis, gain_k, settings), settings.max_delay_s,
                                  settings.grid)
        except SynthesisError:
            return 0.0
        if result.delay_margin_s is not None:
            margin = min(margin, result.delay_margin_s)
    return float(margin)


def _within(delay_s: float, margin_s: float) -> bool:
    if margin_s == 0.0:
        return False
    if not np.isfinite(margin_s):
        return False
    return abs(delay_s - margin_s) <= BAND * margin_s


@dataclass(frozen=True)
class _LaneJob:
    """What every part of a sweep's lanes runs with (units in the names)."""

    model: TeleopModel
    settings: SweepSettings
    lane_gains: np.ndarray
    lane_delays: np.ndarray
    schedules: tuple[np.ndarray, np.ndarray]
    parts: tuple[tuple[int, int], ...]  # (first lane, end) of each part


def _simulate_lanes(job: _LaneJob, first: int, end: int) -> LockstepResult:
    """Lanes ``first:end`` of ``job`` in one lockstep simulation."""
    settings = job.settings
    if settings.mode == "linear":
        scenario = load_scenario("constant-rate")
        operator = parse_operator_spec("constant:fx=0,fy=0")
        environment = "linear"
        steps = int(round(settings.duration_s / job.model.sample_period_s))
        excitation = np.zeros((min(PULSE_SAMPLES, steps), 2))
        excitation[:] = PULSE_FORCE_N
    else:
        scenario = load_scenario("constant-rate")
        operator = parse_operator_spec(CLAY_OPERATOR)
        environment = "clay"
        excitation = None
    injection = sweep_injection(settings)
    passivity = PassivitySettings() if settings.control == "tdpa" else None
    simulator = LockstepSimulator(job.model, scenario, operator, job.lane_gains[first:end],
                                  environment, clay_impl="warp", device=lane_device(settings),
                                  passivity=passivity)
    return simulator.run(settings.duration_s, job.lane_delays[first:end], to_slave=injection,
                         to_master=injection, seed=settings.seed, excitation_N=excitation,
                         window_s=settings.window_s,
                         schedules=tuple(s[:, first:end] for s in job.schedules))


def lane_parts(lane_gains: np.ndarray, workers: int) -> tuple[tuple[int, int], ...]:
    """Contiguous (first, end) lane ranges for ``workers`` processes, split between gains
    (each part holds whole gains, so each runs the stacked compensators of its own gains;
    as even as whole gains allow); fewer parts than workers when there are fewer gains."""
    starts = [0] + [i for i in range(1, lane_gains.size) if lane_gains[i] != lane_gains[i - 1]]
    count = max(1, min(workers, len(starts)))
    bounds = [0]
    for part in range(1, count):
        target = lane_gains.size * part / count
        cut = min(starts[1:], key=lambda start: abs(start - target))
        if cut > bounds[-1]:
            bounds.append(cut)
    bounds.append(lane_gains.size)
    return tuple(zip(bounds[:-1], bounds[1:], strict=True))


#: The fewest lanes worth a process of their own: a tick has a fixed cost many times a
#: lane's, and a forked worker takes a tenth of a second or so to start and set up, so fewer
#: lanes per worker gain little (docs/measurements/sweep_workers.md).
MIN_LANES_PER_WORKER = 100


def auto_workers(lanes: int) -> int:
    """The sweep's workers by default: one per available CPU, each with at least
    :data:`MIN_LANES_PER_WORKER` lanes."""
    return max(1, min(available_workers(), lanes // MIN_LANES_PER_WORKER))


def available_workers() -> int:
    """The CPUs this process may run on."""
    return usable_cpu_count()


def _run_lanes(job: _LaneJob) -> LockstepResult:
    """Every lane of ``job``: the first part in this process, each other one in a process
    forked for it meanwhile (the results joined in lane order: bit for bit the one-process
    run, the schedules having been drawn for every lane)."""
    if len(job.parts) == 1:
        return _simulate_lanes(job, *job.parts[0])
    context = multiprocessing.get_context("fork")
    others: list[_ForkedPart] = []
    try:
        others.extend(_ForkedPart(context, job, index) for index in range(1, len(job.parts)))
        parts = [_simulate_lanes(job, *job.parts[0])]
        parts.extend(other.result() for other in others)
    finally:
        for other in others:
            other.close()
    return concatenate_results(parts)


class _ForkedPart:
    """Part ``index`` of ``job`` in a forked process of its own, which inherits the job (so
    nothing of it is pickled) and sends back its result through a pipe.

    A plain forked process, not a process pool: a pool hands the part over through its
    manager and feeder threads, which wait for this process's GIL while it runs its own part
    (the worker started 30-50 ms late in a 1 s sweep)."""

    def __init__(self, context: Any, job: _LaneJob, index: int) -> None:
        self._receiver, sender = context.Pipe(duplex=False)
        self._process = context.Process(target=_part_worker, args=(job, index, sender),
                                        name=f"sweep part {index}", daemon=True)
        self._process.start()
        sender.close()  # the worker holds its end: end of file here when it stops

    def result(self) -> LockstepResult:
        """The part's result; its error raised again here when the worker failed."""
        try:
            done, value, trace = self._receiver.recv()
        except EOFError:
            self._process.join()
            raise RuntimeError(f"sweep worker {self._process.pid} stopped without a result "
                               f"(exit status {self._process.exitcode})") from None
        self._process.join()
        if not done:
            raise value from RuntimeError(f"in sweep worker {self._process.pid}:\n{trace}")
        return value

    def close(self) -> None:
        """End the worker if it still runs (its own PID) and reap it."""
        if self._process.is_alive():
            self._process.kill()
        self._process.join()
        self._process.close()
        self._receiver.close()


def _part_worker(job: _LaneJob, index: int, sender: Any) -> None:
    """A forked worker's body: part ``index`` of ``job``, sent as (True, result, ""), or the
    error that stopped it as (False, error, traceback)."""
    try:
        message = (True, _simulate_lanes(job, *job.parts[index]), "")
    except Exception as error:  # raised again in the parent, with the worker's traceback
        message = (False, error, traceback.format_exc())
    try:
        sender.send(message)
    except Exception as error:  # what does not pickle goes back as text
        problem = error if message[0] else message[1]
        sender.send((False, RuntimeError(f"{type(problem).__name__}: {problem}"),
                     message[2] or traceback.format_exc()))
    finally:
        sender.close()


def lane_device(settings: SweepSettings) -> str:
    """The Warp device the sweep's clay lanes run on: "cpu" in the linear mode (it has no
    clay), else the settings' device resolved ("auto": CUDA where a device exists)."""
    if settings.mode != "clay":
        return "cpu"
    return resolve_device(settings.device)


def device_problem(device: str, mode: str = "clay") -> str | None:
    """What stops the sweep's clay lanes running on ``device`` (None: nothing): a name that
    is not a Warp device, or, in the clay mode, a CUDA device this machine does not have (the
    linear mode has no clay and never uses the device)."""
    if mode != "clay":
        return device_form_problem(device)
    return clay_device_problem(device)


def can_fork_workers() -> bool:
    """Whether sweep workers may be forked here: on a platform with fork, from a process with
    no other thread (a thread holding a lock at the fork would leave it held in the child)."""
    return "fork" in multiprocessing.get_all_start_methods() and threading.active_count() == 1


def run_sweep(model: TeleopModel, settings: SweepSettings, workers: int = 1) -> SweepResult:
    """Run every cell of the grid as one lane and compare with the analysis. ``workers`` > 1
    splits the lanes between that many forked processes (whole gains each; the same result,
    bit for bit), where :func:`can_fork_workers`; ``wall_seconds`` counts the workers' start
    and the joining of their results."""
    ts = model.sample_period_s
    gains = np.asarray(settings.gains_k, float)
    delay_samples = np.unique(np.rint(np.asarray(settings.delays_s, float) / ts).astype(int))
    lane_gains = np.repeat(gains, delay_samples.size)
    lane_delays = np.tile(delay_samples, gains.size)
    if settings.mode not in MODES:
        raise ValueError(f"mode must be one of {', '.join(MODES)}")
    if settings.control not in CONTROL_MODES:
        raise ValueError(f"control must be one of {', '.join(CONTROL_MODES)}")
    injection = sweep_injection(settings)
    started = time.perf_counter()
    steps = int(round(settings.duration_s / ts))
    schedules = line_schedules(steps, ts, lane_delays, injection, injection, settings.seed)
    device = lane_device(settings)
    forkable = can_fork_workers() and device == "cpu"
    parts = lane_parts(lane_gains, workers if forkable else 1)
    result = _run_lanes(_LaneJob(model, settings, lane_gains, lane_delays, schedules, parts))
    wall = time.perf_counter() - started
    threshold = CLAY_GROWTH_THRESHOLD if settings.mode == "clay" else GROWTH_THRESHOLD
    verdict = growth_verdict(result, settings.reference_start_s, threshold)

    analysed = sweep_model(model, settings.mode)
    margins = np.array([analytic_margin_s(analysed, float(g), ts) for g in gains])
    near_margins = {factor: np.array([analytic_margin_s(analysed, float(g) * factor, ts)
                                      for g in gains]) for factor in (1 - BAND, 1 + BAND)}
    shape = (gains.size, delay_samples.size)
    delays_s = delay_samples * ts
    analytic_stable = delays_s[None, :] < margins[:, None]
    in_band = np.zeros(shape, bool)
    for i in range(gains.size):
        low, high = near_margins[1 + BAND][i], near_margins[1 - BAND][i]
        for j, delay in enumerate(delays_s):
            # Near the boundary in delay, or a gain within the band on the other side of it.
            other_side = (delay < low) != (delay < margins[i]) or (delay < high) != (
                delay < margins[i])
            in_band[i, j] = _within(float(delay), margins[i]) or other_side
    swept = SweepResult(
        settings=settings, sample_period_s=ts, delay_samples=delay_samples,
        growing=verdict.growing.reshape(shape), analytic_stable=analytic_stable,
        in_band=in_band, peak_force_N=result.peak_handle_force_N.max(axis=1).reshape(shape),
        position_error_rms_m=result.position_error_rms_m.max(axis=1).reshape(shape),
        amplitude_ratio=verdict.amplitude_ratio.reshape(shape),
        energy_ratio=verdict.energy_ratio.reshape(shape), margin_s=margins,
        simulated_seconds=result.simulated_seconds, wall_seconds=wall,
        max_abs_force_N=np.maximum(result.peak_handle_force_N.max(axis=1),
                                   result.peak_tool_force_N.max(axis=1)).reshape(shape),
    )
    swept.extra["per_cell"] = per_cell(swept, result)
    swept.extra["workers"] = len(parts)
    swept.extra["device"] = device
    return swept


def run_sweep_grid(model: TeleopModel, settings: SweepSettings, jitters_s: tuple[float, ...],
                   losses: tuple[float, ...], workers: int = 1) -> tuple[dict, list[SweepResult]]:
    """The sweep at every (jitter, loss) pair, one run each (``workers``: as
    :func:`run_sweep`): the summary sums today's counts over the runs and lists every cell in
    ``per_cell``."""
    results = [run_sweep(model, replace(settings, jitter_s=float(jitter),
                                        loss_probability=float(loss)), workers)
               for jitter in jitters_s for loss in losses]
    summaries = [result.summary() for result in results]
    summary = dict(summaries[0])
    for key in ("cells", "bounded", "unbounded", "agree", "disagree", "disagree_outside_band",
                "simulated_seconds", "wall_seconds"):
        summary[key] = round(sum(item[key] for item in summaries), 3)
    summary["sim_per_wall"] = round(summary["simulated_seconds"]
                                    / max(summary["wall_seconds"], 1e-9), 1)
    summary["bursty"] = settings.bursty
    summary["per_cell"] = [cell for result in results for cell in result.extra["per_cell"]]
    return summary, results


def write_csv(result: SweepResult, path: str) -> None:
    """The cells as CSV, one row per cell."""
    import csv

    rows = result.rows()
    with open(path, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def plot_heatmap(result: SweepResult, path: str, model: TeleopModel) -> None:
    """Heat map of the cells' peak force (log colour), growing cells hatched, disagreeing
    cells circled, with the analytic boundary tau*(k) drawn over them."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    gains = np.asarray(result.settings.gains_k, float)
    delays_ms = result.delay_samples * result.sample_period_s * 1e3
    fig, ax = plt.subplots(figsize=(8, 5))
    peak = np.log10(np.maximum(np.nan_to_num(result.peak_force_N, nan=1e12, posinf=1e12),
                               1e-6))
    mesh = ax.pcolormesh(delays_ms, gains, np.minimum(peak, 6), shading="nearest",
                         cmap="viridis")
    fig.colorbar(mesh, ax=ax, label="log10 peak handle force (N)")
    grow_i, grow_j = np.nonzero(result.growing)
    ax.scatter(delays_ms[grow_j], gains[grow_i], marker="x", color="white", s=14,
               label="lockstep: growing")
    bad_i, bad_j = np.nonzero(~result.agree)
    ax.scatter(delays_ms[bad_j], gains[bad_i], marker="o", facecolors="none",
               edgecolors="red", s=60, label="disagrees with the analysis")
    analysed = sweep_model(model, result.settings.mode)
    fine = np.linspace(gains.min(), gains.max(), 60)
    curve = np.array([analytic_margin_s(analysed, float(g), result.sample_period_s)
                      for g in fine]) * 1e3
    ax.plot(np.minimum(curve, delays_ms.max() * 1.05), fine, color="orange", lw=2,
            label="sampled analysis: delay margin")
    ax.set_xlim(delays_ms.min() - 0.5, delays_ms.max() + 0.5)
    ax.set_xlabel("round-trip delay (ms)")
    ax.set_ylabel("Ch1 gain k")
    ax.set_title(f"Latency sweep ({result.settings.mode} loop)")
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


@dataclass(frozen=True)
class LockstepMargin:
    """The delay margin the lockstep measures for one gain: the loop is bounded at
    ``bounded_samples`` and grows at ``growing_samples`` = bounded + 1 round-trip samples;
    ``margin_s`` is the midpoint, good to +-Ts/2."""

    gain_k: float
    bounded_samples: int
    growing_samples: int
    margin_s: float


def lockstep_margin(model: TeleopModel, gain_k: float, delays_samples: np.ndarray,
                    duration_s: float = 3.0) -> LockstepMargin:
    """Run the linear loop at ``gain_k`` for every round-trip delay in ``delays_samples``
    (consecutive whole samples, one lane each, in one run) and locate the boundary: the
    first delay from which every longer one grows. Raises ValueError when the range does
    not contain it."""
    delays = np.arange(int(np.min(delays_samples)), int(np.max(delays_samples)) + 1)
    ts = model.sample_period_s
    simulator = LockstepSimulator(model, load_scenario("constant-rate"),
                                  parse_operator_spec("constant:fx=0,fy=0"),
                                  np.full(delays.size, float(gain_k)), "linear")
    excitation = np.full((PULSE_SAMPLES, 2), PULSE_FORCE_N)
    result = simulator.run(duration_s, delays, excitation_N=excitation)
    growing = growth_verdict(result).growing
    if growing[0] or not growing[-1]:
        raise ValueError(f"k = {gain_k:g}: the boundary is not inside delays "
                         f"{delays[0]}..{delays[-1]} samples")
    # Every longer delay grows from the first index of the last run of growing lanes.
    first = int(np.flatnonzero(~growing)[-1]) + 1
    bounded, grows = int(delays[first - 1]), int(delays[first])
    return LockstepMargin(float(gain_k), bounded, grows, (bounded + grows) / 2.0 * ts)
