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
"""

from __future__ import annotations

import numpy as np

from haptic.common.wire.injection import InjectionConfig


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
    target = np.broadcast_to(ticks + offset_samples + delays[None, :], (steps, lanes)).copy()
    lost = np.zeros((steps, lanes), bool)
    if injection is not None and injection.active:
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


class DelayLine:
    """A ring buffer of sent messages (lanes, channels) read through a source schedule."""

    def __init__(self, schedule: np.ndarray, channels: int, initial: np.ndarray | None = None
                 ) -> None:
        self.schedule = schedule
        steps, lanes = schedule.shape
        ticks = np.arange(steps)[:, None]
        lag = np.where(schedule >= 0, ticks - schedule, 0)
        self.history = int(lag.max()) + 1 if steps else 1
        self.buffer = np.zeros((self.history, lanes, channels))
        self.initial = np.zeros((lanes, channels)) if initial is None else np.asarray(
            initial, float).reshape(lanes, channels)
        self._lanes = np.arange(lanes)
        self._constant = bool(np.all(schedule == schedule[:, :1])) if steps else True
        # a lane's source never decreases: from this tick on every lane has a message
        started = np.flatnonzero((schedule >= 0).all(axis=1))
        self._all_started_from = int(started[0]) if started.size else steps
        self._rows = self.buffer.reshape(self.history * lanes, channels)  # a view

    def send(self, tick: int, message: np.ndarray) -> None:
        """Store the message every lane sends at ``tick``."""
        self.buffer[tick % self.history] = message

    def receive(self, tick: int) -> np.ndarray:
        """The newest message each lane can read at ``tick`` (lanes, channels)."""
        source = self.schedule[tick]
        if self._constant:
            first = int(source[0])
            if first < 0:
                return self.initial
            return self.buffer[first % self.history].copy()
        if tick >= self._all_started_from:  # one gather from the flat rows
            return np.take(self._rows, (source % self.history) * self._lanes.size
                           + self._lanes, axis=0)
        rows = self.buffer[source % self.history, self._lanes]
        return np.where((source >= 0)[:, None], rows, self.initial)
