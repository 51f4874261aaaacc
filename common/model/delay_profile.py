"""A one-way delay that changes over a run: a step (2 ms, then 40 ms from t = 3 s) or a ramp.

A profile is written as one string, the same in TOML (``[link.<side>.injection]
delay_profile``), on the programs' command line (``--delay-profile``) and in ``haptic-sim``::

    "<shape> t0:d0 t1:d1 ..."      e.g. "step 0:0.002 3:0.040" or "linear 0:0.002 5:0.040"

``shape`` is ``step`` (d_i holds from t_i until t_{i+1}) or ``linear`` (straight lines
between the points); times are s since the start of the run (strictly increasing, >= 0),
delays s (>= 0, at most :data:`MAX_DELAY_S`). Before t0 the delay is d0, after the last point
the last delay. The empty string is no profile. The profile's delay is *added* to the
injection's constant ``delay_s``.

Evaluation is pure Python (``bisect`` over at most :data:`MAX_POINTS` points, no numpy: about
a microsecond), so the receive path calls :meth:`DelayProfile.delay_s` for every message.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from dataclasses import dataclass

SHAPES = ("step", "linear")
#: Largest delay a profile may hold, s (the injection's own bound).
MAX_DELAY_S = 10.0
#: Most points a profile may have.
MAX_POINTS = 64


class DelayProfileError(ValueError):
    """A profile string that cannot be read; the message says which part and why."""


@dataclass(frozen=True)
class DelayProfile:
    """A delay (s) as a function of time since the run's start (s); see the module doc."""

    shape: str
    times_s: tuple[float, ...]
    delays_s: tuple[float, ...]

    def __post_init__(self) -> None:
        if self.shape not in SHAPES:
            raise DelayProfileError(f"shape must be one of {', '.join(SHAPES)} "
                                    f"(got {self.shape!r})")
        if not self.times_s or len(self.times_s) != len(self.delays_s):
            raise DelayProfileError("needs at least one time:delay point")
        if len(self.times_s) > MAX_POINTS:
            raise DelayProfileError(f"at most {MAX_POINTS} points (got {len(self.times_s)})")
        previous = -math.inf
        for t, d in zip(self.times_s, self.delays_s, strict=True):
            if not (math.isfinite(t) and t >= 0.0):
                raise DelayProfileError(f"time {t!r} must be a finite number >= 0 s")
            if not t > previous:
                raise DelayProfileError(f"times must increase strictly (got {t:g} after "
                                        f"{previous:g})")
            if not (math.isfinite(d) and 0.0 <= d <= MAX_DELAY_S):
                raise DelayProfileError(f"delay {d!r} must be in [0, {MAX_DELAY_S:g}] s")
            previous = t

    @property
    def max_delay_s(self) -> float:
        """The largest delay of the profile, s."""
        return max(self.delays_s)

    @property
    def initial_delay_s(self) -> float:
        """The delay at the start (t = 0), s."""
        return self.delay_s(0.0)

    def delay_s(self, time_s: float) -> float:
        """The delay at ``time_s`` (s since the run's start), s."""
        times = self.times_s
        index = bisect_right(times, time_s) - 1  # the last point at or before time_s
        if index < 0:
            return self.delays_s[0]
        if self.shape == "step" or index == len(times) - 1:
            return self.delays_s[index]
        t0, t1 = times[index], times[index + 1]
        d0, d1 = self.delays_s[index], self.delays_s[index + 1]
        return d0 + (d1 - d0) * (time_s - t0) / (t1 - t0)

    def describe(self) -> str:
        """The profile in its own string form."""
        points = " ".join(f"{t:g}:{d:g}" for t, d in zip(self.times_s, self.delays_s,
                                                         strict=True))
        return f"{self.shape} {points}"


def parse_delay_profile(text: str) -> DelayProfile | None:
    """The profile of ``text`` (``None`` for an empty string). Raises
    :class:`DelayProfileError` naming the part that is wrong."""
    words = text.split()
    if not words:
        return None
    shape, points = words[0], words[1:]
    if shape not in SHAPES:
        raise DelayProfileError(f"must start with a shape, one of {', '.join(SHAPES)} "
                                f"(got {shape!r}), e.g. 'step 0:0.002 3:0.040'")
    times, delays = [], []
    for point in points:
        t, colon, d = point.partition(":")
        try:
            if not colon:
                raise ValueError
            times.append(float(t))
            delays.append(float(d))
        except ValueError:
            raise DelayProfileError(f"point {point!r} is not time_s:delay_s") from None
    return DelayProfile(shape, tuple(times), tuple(delays))


def delay_profile_problem(text: str) -> str | None:
    """Why ``text`` is not a valid profile, or ``None`` (a configuration check)."""
    try:
        parse_delay_profile(text)
    except DelayProfileError as error:
        return str(error)
    return None
