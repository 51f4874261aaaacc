"""Exact sample delay lines between the lockstep nodes, with the link's jitter and loss.

A message sent at tick ``j`` becomes receivable at tick ``j + offset + d + e_j``: ``offset``
is the line's structural sample (0 for the handle line, 1 for the tool line: the slave's
force describes the end of its step, t_{j+1}; see docs/lockstep.md), ``d`` the lane's delay
in whole samples and ``e_j`` the extra samples of the injected delay and jitter,
``ceil((delay_s + profile(j Ts) + jitter_j) / Ts)`` (``profile``: the injection's delay
profile, :mod:`haptic.common.model.delay_profile`, with t = 0 at tick 0). The receiver at
tick ``k`` reads the newest message it has (the largest ``j`` receivable by ``k``); a lost
message is never receivable, so the receiver keeps the previous one; before the first
message it reads the initial value.

Jitter and loss follow :mod:`haptic.common.wire.injection` (same distributions and bounds, the
same Gilbert-Elliott chain, ``preserve_order`` as a running maximum of the targets); the
draws come from the seeded generator given here, vectorised over ticks and lanes, so they
are not the same stream of numbers a real :class:`~haptic.common.wire.injection.Impairment`
would draw.

:class:`DelayLine` reads every lane in one Warp kernel launch on the CPU (a recorded launch
over its own arrays, common/runtime/replayed_launch.py), which also gives what the receiving
program's link would say of each lane's message (fresh, silence, send tick and time, flags):
about 20 numpy calls a tick and line before.
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np
import warp as wp

from haptic.common.runtime.replayed_launch import ReplayedLaunch, host_array
from haptic.common.wire.injection import InjectionConfig

# The programs print JSON on stdout: Warp must not announce itself there.
wp.config.log_level = wp.LOG_WARNING

DEVICE = "cpu"


def jitter_draws_s(config: InjectionConfig, shape: tuple[int, ...],
                   rng: np.random.Generator) -> np.ndarray:
    """Jitter (s) per message, in [0, jitter_s], distributed as the link's injection."""
    bound = config.jitter_s
    if bound <= 0.0:
        return np.zeros(shape)
    if config.jitter_distribution == "uniform":
        draws = rng.random(shape) * bound
    elif config.jitter_distribution == "normal":
        draws = bound * (0.5 + rng.standard_normal(shape) / 6.0)
    else:
        draws = rng.exponential(bound / 5.0, shape)
    return np.clip(draws, 0.0, bound)


def loss_mask(config: InjectionConfig, shape: tuple[int, int],
              rng: np.random.Generator) -> np.ndarray:
    """True where a message (ticks, lanes) is lost: independent and Gilbert-Elliott bursts."""
    steps, lanes = shape
    lost = np.zeros(shape, bool)
    if config.loss_probability > 0.0:
        lost |= rng.random(shape) < config.loss_probability
    if config.burst_enter_probability > 0.0 and config.burst_loss_probability > 0.0:
        draws = rng.random((steps, lanes, 2))
        in_burst = np.zeros(lanes, bool)
        for k in range(steps):
            leave = in_burst & (draws[k, :, 0] < config.burst_exit_probability)
            enter = ~in_burst & (draws[k, :, 0] < config.burst_enter_probability)
            in_burst = (in_burst & ~leave) | enter
            lost[k] |= in_burst & (draws[k, :, 1] < config.burst_loss_probability)
    return lost


def source_schedule(steps: int, delay_samples: np.ndarray, offset_samples: int,
                    period_s: float, injection: InjectionConfig | None = None,
                    rng: np.random.Generator | None = None) -> np.ndarray:
    """For each receive tick and lane, the send tick of the newest receivable message
    (-1: none yet), shape (steps, lanes)."""
    delays = np.atleast_1d(np.asarray(delay_samples, np.int64))
    if np.any(delays < 0):
        raise ValueError("delays must be >= 0 samples")
    lanes = delays.size
    ticks = np.arange(steps, dtype=np.int64)[:, None]
    if injection is None or not injection.active:
        # every message arrives, each line's lag fixed: tick t reads the one sent at
        # t - offset - delay (what the scatter below gives, without its cost)
        return np.maximum(ticks - offset_samples - delays[None, :], -1)
    target = np.broadcast_to(ticks + offset_samples + delays[None, :], (steps, lanes)).copy()
    if rng is None:
        raise ValueError("injecting jitter or loss needs a seeded generator")
    extra_s = injection.delay_s + jitter_draws_s(injection, (steps, lanes), rng)
    profile = injection.delay_profile
    if profile is not None:
        extra_s = extra_s + np.array([profile.delay_s(j * period_s)
                                      for j in range(steps)])[:, None]
    target += np.ceil(extra_s / period_s - 1e-9).astype(np.int64)
    if injection.preserve_order:
        target = np.maximum.accumulate(target, axis=0)
    lost = loss_mask(injection, (steps, lanes), rng)
    source = np.full((steps, lanes), -1, np.int64)
    delivered = (~lost) & (target < steps)
    rows, lane_index = np.nonzero(delivered)
    np.maximum.at(source, (target[rows, lane_index], lane_index), rows)
    return np.maximum.accumulate(source, axis=0)


@wp.struct
class LineConstants:
    """What the receive kernel needs besides the arrays (ticks, s, ns)."""

    history: wp.int64  # slots of the ring buffer
    period_s: wp.float64  # Ts, s
    period_ns: wp.float64  # Ts, ns (as the programs' send times are stamped)


@functools.cache
def receive_kernel(channels: int, message_columns: int, flag_column: int) -> Any:
    """The receive kernel of a line of ``channels`` columns whose first ``message_columns``
    go to ``columns`` and whose ``flag_column`` holds the flags: every loop over the columns
    of constant length (unrolled; about half the time of the same loops over an array's
    shape on Warp's CPU device). One Warp module per layout."""

    @wp.kernel(module=f"{__name__}.receive_{channels}_{message_columns}_{flag_column}")
    def receive(schedule: wp.array2d(dtype=wp.int64), tick: wp.array(dtype=wp.int64),
                buffer: wp.array3d(dtype=wp.float64), initial: wp.array2d(dtype=wp.float64),
                runup_lag: wp.array(dtype=wp.int64), constants: LineConstants,
                rows: wp.array2d(dtype=wp.float64), previous: wp.array(dtype=wp.int64),
                last_fresh: wp.array(dtype=wp.int64), fresh: wp.array(dtype=wp.bool),
                silence_s: wp.array(dtype=wp.float64), sent: wp.array(dtype=wp.int64),
                send_time_ns: wp.array(dtype=wp.int64), flags: wp.array(dtype=wp.int64),
                columns: wp.array2d(dtype=wp.float64)):
        lane = wp.tid()
        k = tick[0]
        source = schedule[k, lane]
        if source >= wp.int64(0):
            slot = source % constants.history
            for c in range(channels):
                rows[lane, c] = buffer[slot, lane, c]
        else:
            for c in range(channels):
                rows[lane, c] = initial[lane, c]
        new = source != previous[lane] or source < wp.int64(0)
        previous[lane] = source
        fresh[lane] = new
        if new:
            last_fresh[lane] = k
        silence_s[lane] = wp.float64(k - last_fresh[lane]) * constants.period_s
        send_tick = source
        if source < wp.int64(0):
            send_tick = k - runup_lag[lane]
        sent[lane] = send_tick
        send_time_ns[lane] = wp.int64(wp.float64(send_tick) * constants.period_ns)
        flags[lane] = wp.int64(rows[lane, flag_column])
        for c in range(message_columns):
            columns[lane, c] = rows[lane, c]
        columns[lane, message_columns] = wp.float64(send_tick)

    return receive


class DelayLine:
    """A ring buffer of sent messages (lanes, channels) read through a source schedule.

    :meth:`receive` (one Warp launch for every lane, on the CPU) gives each lane's newest
    message and what the receiver's link would say of it, in arrays kept between ticks
    (valid until the next receive): :attr:`fresh` (a new message, or one of the run-up's
    before the first), :attr:`silence_s` (s since the lane's last fresh one), :attr:`sent`
    (its send tick; a run-up message was sent ``runup_lag`` ticks before it is read),
    :attr:`send_time_ns` (``sent`` Ts in ns), :attr:`flags` (its ``flag_column`` as an
    int) and :attr:`columns` (its first ``message_columns`` columns, then ``sent``).
    ``period_s``: Ts, s.
    """

    def __init__(self, schedule: np.ndarray, channels: int, initial: np.ndarray | None = None,
                 *, period_s: float = 1.0, runup_lag: np.ndarray | int = 0,
                 message_columns: int | None = None, flag_column: int = 0) -> None:
        self.schedule = np.ascontiguousarray(schedule, np.int64)
        steps, lanes = self.schedule.shape
        ticks = np.arange(steps)[:, None]
        lag = np.where(self.schedule >= 0, ticks - self.schedule, 0)
        self.history = int(lag.max()) + 1 if steps else 1
        self.buffer = np.zeros((self.history, lanes, channels))
        self.initial = np.zeros((lanes, channels)) if initial is None else np.ascontiguousarray(
            np.asarray(initial, float).reshape(lanes, channels))
        message_columns = channels if message_columns is None else message_columns
        if not (0 <= message_columns <= channels and 0 <= flag_column < max(channels, 1)):
            raise ValueError("message_columns and flag_column must be columns of the line")
        self.rows = np.zeros((lanes, channels))
        self.fresh = np.zeros(lanes, bool)
        self.silence_s = np.zeros(lanes)
        self.sent = np.zeros(lanes, np.int64)
        self.send_time_ns = np.zeros(lanes, np.int64)
        self.flags = np.zeros(lanes, np.int64)
        self.columns = np.zeros((lanes, message_columns + 1))
        self._runup_lag = np.ascontiguousarray(np.broadcast_to(
            np.asarray(runup_lag, np.int64), (lanes,)))
        self._previous = np.full(lanes, -2, np.int64)
        self._last_fresh = np.zeros(lanes, np.int64)
        self._tick = np.zeros(1, np.int64)
        constants = LineConstants()
        constants.history = self.history
        constants.period_s = float(period_s)
        constants.period_ns = float(period_s) * 1e9
        self._constants = constants
        self._kernel = receive_kernel(channels, message_columns, flag_column)
        self._launch: ReplayedLaunch | None = None

    def _bind(self) -> ReplayedLaunch:
        """The recorded launch over this line's arrays (zero-copy views of them)."""
        f64, i64 = wp.float64, wp.int64

        self._bound = [host_array(array, dtype) for array, dtype in (
            (self.schedule, i64), (self._tick, i64), (self.buffer, f64), (self.initial, f64),
            (self._runup_lag, i64))]
        outputs = [host_array(array, dtype) for array, dtype in (
            (self.rows, f64), (self._previous, i64), (self._last_fresh, i64),
            (self.fresh, wp.bool), (self.silence_s, f64), (self.sent, i64),
            (self.send_time_ns, i64), (self.flags, i64), (self.columns, f64))]
        self._bound += outputs
        return ReplayedLaunch(wp.launch(
            self._kernel, dim=self.rows.shape[0], device=DEVICE,
            inputs=[*self._bound[:5], self._constants, *outputs], record_cmd=True))

    def send(self, tick: int, message: np.ndarray) -> None:
        """Store the message every lane sends at ``tick``."""
        self.buffer[tick % self.history] = message

    def slot(self, tick: int) -> np.ndarray:
        """The message every lane sends at ``tick`` (lanes, channels), to write in place (as
        :meth:`send` would store it)."""
        return self.buffer[tick % self.history]

    def receive(self, tick: int) -> np.ndarray:
        """The newest message each lane can read at ``tick`` (lanes, channels), with the
        arrival figures (see the class); ticks in order, from 0."""
        launch = self._launch
        if launch is None:
            launch = self._launch = self._bind()
        self._tick[0] = tick
        launch.launch()
        return self.rows
