"""The supervision rules both sides' quiet-lane kernels share, as Warp functions
(master/quiet_kernel.py, slave_sim/quiet_kernel.py call them per lane).

A lane is quiet when its supervisor would change nothing this tick. Two parts of that rule
are the same on both sides (common/runtime/supervision.py):

- :func:`watchdog_stays_ok`: the supervisor is steady (its ``steady()``: running with the
  watchdog ``ok`` and nothing latched) and the link not silent, the silence (s) not above
  the watchdog's ``max_message_age_s`` (s);
- :func:`flags_quiet`: the peer's newest flags, masked, equal the quiet value (the peer's
  forces enabled and no ``STOPPING``, plus each side's own bits).

Both kernels report their loud lanes alike (:func:`count_loud`), so that the caller reads one
integer a tick and looks at the lanes only when it is not zero.

Comparisons are written as the supervisors' Python is, so a NaN fails them alike and the
kernels agree with the objects bit for bit.
"""

from __future__ import annotations

import warp as wp

# The programs print JSON on stdout: Warp must not announce itself there.
wp.config.log_level = wp.LOG_WARNING


@wp.func
def watchdog_stays_ok(steady: wp.bool, silence_s: wp.float64, max_age_s: wp.float64) -> bool:
    """The supervisor is steady and the silence (s) is not above the message age limit (s):
    its watchdog stays ``ok`` this tick."""
    return steady and (not (silence_s > max_age_s))


@wp.func
def flags_quiet(flags: wp.int64, mask: wp.int64, value: wp.int64) -> bool:
    """The message's flag bits under ``mask`` equal ``value``."""
    return (flags & mask) == value


@wp.func
def count_loud(quiet: bool, loud_count: wp.array(dtype=wp.int32)):
    """Adds one to ``loud_count[0]`` for a lane that is not quiet."""
    if not quiet:
        wp.atomic_add(loud_count, 0, 1)


__all__ = ["count_loud", "flags_quiet", "watchdog_stays_ok"]
