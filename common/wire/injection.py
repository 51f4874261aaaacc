"""Network impairment injected on the receiving side of the link: delay, jitter and loss.

Everything here is pure (no I/O, no clock): the receive path asks :class:`Impairment` for a
message's fate and its target delivery time, relative to the message's send time.

- One-way delay ``delay_s`` plus jitter: the message is delivered no earlier than
  ``send_time + delay_s + j``, where ``j`` is drawn from the jitter distribution and always lies
  in ``[0, jitter_s]`` (so ``jitter_s`` is a hard bound for every distribution):

  - ``uniform``: ``j ~ U(0, jitter_s)``;
  - ``normal``: a normal with mean ``jitter_s / 2`` and standard deviation ``jitter_s / 6``,
    clipped to ``[0, jitter_s]``;
  - ``exponential``: an exponential with mean ``jitter_s / 5``, clipped to ``jitter_s`` (mostly
    small extra delay with a tail).

  The real network delay is part of the target: a message whose real delay already exceeds the
  target is delivered as soon as it arrives, with no extra wait. With ``preserve_order`` the
  target is also never earlier than the previous message's (a FIFO link such as TCP), so jitter
  does not reorder messages.
- Loss: independent (each message lost with ``loss_probability``) and bursty, a Gilbert-Elliott
  two-state chain stepped once per message: good -> bad with ``burst_enter_probability``,
  bad -> good with ``burst_exit_probability``, and in the bad state a message is lost with
  ``burst_loss_probability``. Mean burst length is ``1 / burst_exit_probability`` messages. A
  message is lost when either mechanism loses it.

- A delay profile (:mod:`haptic.common.model.delay_profile`, ``delay_profile``): a delay that
  changes over the run (a step, a ramp) added to ``delay_s``; its time is the message's send
  time minus the send time of the first message the link accepted (t = 0: the peer's first
  message).

Every random draw comes from the seeded :class:`numpy.random.Generator` given to the
:class:`Impairment`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from haptic.common.config.link_schema import JITTER_DISTRIBUTIONS
from haptic.common.model.delay_profile import DelayProfile

_BLOCK = 1024


@dataclass(frozen=True)
class InjectionConfig:
    """What one side's receiving link injects, one way. Times in s, probabilities in 0..1."""

    delay_s: float = 0.0
    jitter_s: float = 0.0
    jitter_distribution: str = "uniform"
    preserve_order: bool = True
    loss_probability: float = 0.0
    burst_enter_probability: float = 0.0
    burst_exit_probability: float = 1.0
    burst_loss_probability: float = 1.0
    delay_profile: DelayProfile | None = None
    """A delay over time added to ``delay_s`` (None: constant)."""

    def __post_init__(self) -> None:
        for name in ("delay_s", "jitter_s"):  # an infinite one overflows the ns arithmetic
            value = getattr(self, name)
            if not 0.0 <= value < math.inf:
                raise ValueError(f"{name} must be finite and >= 0 (got {value})")
        if self.jitter_distribution not in JITTER_DISTRIBUTIONS:
            raise ValueError(
                f"jitter_distribution must be one of {', '.join(JITTER_DISTRIBUTIONS)} "
                f"(got {self.jitter_distribution!r})"
            )
        for name in ("loss_probability", "burst_enter_probability", "burst_loss_probability"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"{name} must be in [0, 1] (got {value})")
        if not 0.0 < self.burst_exit_probability <= 1.0:
            raise ValueError(
                f"burst_exit_probability must be in (0, 1] (got {self.burst_exit_probability})"
            )

    @property
    def active(self) -> bool:
        """Whether anything is injected at all."""
        return (
            self.delay_s > 0.0
            or (self.delay_profile is not None and self.delay_profile.max_delay_s > 0.0)
            or self.jitter_s > 0.0
            or self.loss_probability > 0.0
            or (self.burst_enter_probability > 0.0 and self.burst_loss_probability > 0.0)
        )

    @property
    def max_extra_delay_s(self) -> float:
        """The largest delay the injection can add, s."""
        profile = 0.0 if self.delay_profile is None else self.delay_profile.max_delay_s
        return self.delay_s + profile + self.jitter_s


class Impairment:
    """The random part of the injection: per message, lost or not and the target delay.

    Holds the Gilbert-Elliott state and the last target (for ``preserve_order``); random numbers
    are drawn from ``rng`` in blocks so a message costs no numpy call.
    """

    def __init__(self, config: InjectionConfig, rng: np.random.Generator) -> None:
        self.config = config
        self._rng = rng
        self._uniforms = np.empty(0)
        self._next = 0
        self.in_burst = False
        self._delay_ns = round(config.delay_s * 1e9)
        self._jitter_ns = config.jitter_s * 1e9
        self._last_target_ns = 0
        self._profile = config.delay_profile
        self.profile_origin_ns: int | None = None
        """t = 0 of the delay profile: the send time of the first message asked about."""

    def _uniform(self) -> float:
        if self._next >= len(self._uniforms):
            self._uniforms = self._rng.random(_BLOCK)
            self._next = 0
        value = self._uniforms[self._next]
        self._next += 1
        return float(value)

    def lost(self) -> bool:
        """Step the loss models once (one message) and say whether it is lost."""
        c = self.config
        lost = c.loss_probability > 0.0 and self._uniform() < c.loss_probability
        if c.burst_enter_probability > 0.0:
            if self.in_burst:
                if self._uniform() < c.burst_exit_probability:
                    self.in_burst = False
            elif self._uniform() < c.burst_enter_probability:
                self.in_burst = True
            if self.in_burst and self._uniform() < c.burst_loss_probability:
                lost = True
        return lost

    def jitter_ns(self) -> int:
        """One draw of the jitter, ns, in [0, jitter_s]."""
        if self._jitter_ns <= 0.0:
            return 0
        c = self.config
        if c.jitter_distribution == "uniform":
            j = self._uniform() * self._jitter_ns
        elif c.jitter_distribution == "normal":
            j = self._jitter_ns * (0.5 + self._rng.standard_normal() / 6.0)
        else:
            j = self._rng.exponential(self._jitter_ns / 5.0)
        return int(min(max(j, 0.0), self._jitter_ns))

    def target_ns(self, send_time_ns: int) -> int:
        """The earliest delivery time of a message sent at ``send_time_ns``, ns (same clock)."""
        target = send_time_ns + self._delay_ns + self.jitter_ns()
        profile = self._profile
        if profile is not None:
            origin = self.profile_origin_ns
            if origin is None:
                origin = self.profile_origin_ns = send_time_ns
            target += round(profile.delay_s((send_time_ns - origin) * 1e-9) * 1e9)
        if self.config.preserve_order:
            if target < self._last_target_ns:
                target = self._last_target_ns
            self._last_target_ns = target
        return target
