"""NVIDIA Warp kernel of the lockstep's quiet lanes on the slave side
(lockstep/quiet_lanes.py, ``SlaveQuietLanes``): for every lane in one launch,
whether its message needs the lane's guard and supervisor, and where it does not, the
message's values taken.

A lane is quiet when its :class:`~haptic.slave_sim.input_guard.InputGuard` would take the
fresh message as it is and its :class:`~haptic.slave_sim.supervisor.SlaveSupervisor` would
change nothing (or no message came and the supervisor has nothing to change). Mirrors, per
lane and comparison by comparison:

- :meth:`InputGuard.admit` for a message it takes unchanged: the guard not faulted, every
  value finite, no force beyond ``force_trip_N``, the position inside its box, the same sender
  epoch as the last accepted message with no jump beyond ``velocity_trip_m_per_s dt +
  jump_margin_m``, and neither saturation at ``force_limit_N`` nor the rate limit, ``dt``
  credited as :class:`~haptic.common.wire.send_clock.SendClock` credits it (and the clock
  then moved on as :meth:`SendClock.accept` moves it);
- :meth:`SlaveSupervisor.update` returning ``NONE``: :meth:`SlaveSupervisor.steady`, the
  watchdog not silent, the message (where one came) carrying FORCES_ENABLED, and the tool
  inside its work area.

The supervisor's rules the master's kernel shares are common/runtime/quiet_rules.py's.
tests/lockstep/test_quiet_lanes.py runs every lane through both, bit for bit. One launch
replaces about 40 numpy calls on (lanes, 2) arrays, whose cost does not grow with the lane
count (bench/latency_sweep.py measures the sweep's speed). float64 throughout; every constant
comes in :class:`GuardLimits`, so no literal is rounded to float32.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import warp as wp

from haptic.common.runtime.quiet_rules import count_loud, flags_quiet, watchdog_stays_ok
from haptic.common.runtime.replayed_launch import InPlaceInputs, ReplayedLaunch, host_array
from haptic.common.wire.messages import Flags
from haptic.common.wire.send_clock import LEAD_RISE_DIVISOR
from haptic.slave_sim.input_guard import InputGuardSettings

# The programs print JSON on stdout: Warp must not announce itself there.
wp.config.log_level = wp.LOG_WARNING

DEVICE = "cpu"
#: The flag bits of the master's message that decide a quiet lane, and the value they must
#: have: its forces enabled, and not its last message (``STOPPING``, never quiet).
QUIET_MASK = int(Flags.FORCES_ENABLED) | int(Flags.STOPPING)
QUIET_VALUE = int(Flags.FORCES_ENABLED)


@wp.struct
class GuardLimits:
    """The input guard's settings and the period as the kernel reads them (SI units)."""

    period_s: wp.float64
    ns_to_s: wp.float64  # 1e-9, s per ns (a float64 field: a literal would be float32)
    force_limit_N: wp.float64
    force_trip_N: wp.float64
    force_rate_limit_N_per_s: wp.float64
    position_min_x_m: wp.float64
    position_min_y_m: wp.float64
    position_max_x_m: wp.float64
    position_max_y_m: wp.float64
    velocity_trip_m_per_s: wp.float64
    jump_margin_m: wp.float64
    jitter_allowance_ns: wp.int64
    lead_rise_divisor: wp.int64  # send_clock.LEAD_RISE_DIVISOR
    quiet_mask: wp.int64  # QUIET_MASK
    quiet_value: wp.int64  # QUIET_VALUE


@wp.func
def plain_axis(force: wp.float64, position: wp.float64, last_force: wp.float64,
               step: wp.float64, low: wp.float64, high: wp.float64,
               limits: GuardLimits) -> bool:
    """One axis of a message the guard takes unchanged: finite, no trip, inside the box, no
    saturation, no rate limit (NaN fails every comparison)."""
    if not (wp.isfinite(force) and wp.isfinite(position)):
        return False
    if not (wp.abs(force) <= limits.force_trip_N):
        return False
    if not (position >= low and position <= high):
        return False
    if not (force >= -limits.force_limit_N and force <= limits.force_limit_N):
        return False
    lowest = last_force - step
    highest = last_force + step
    return force >= lowest and force <= highest


@wp.func
def guard_takes_plain(lane: int, now: wp.int64, force: wp.array2d(dtype=wp.float64),
                      position: wp.array2d(dtype=wp.float64), send_ns: wp.array(dtype=wp.int64),
                      handle_force: wp.array2d(dtype=wp.float64),
                      handle_position: wp.array2d(dtype=wp.float64),
                      guard_credited_ns: wp.array(dtype=wp.int64),
                      guard_lead_ns: wp.array(dtype=wp.int64), limits: GuardLimits):
    """:meth:`InputGuard.admit`'s plain path for a fresh message of the guard's epoch, ``now``
    the loop time (ns): whether the guard takes it as it is, and its send time as
    :meth:`SendClock.credit` credits it (ns)."""
    # SendClock.credit and span_s
    credited_ns = wp.min(send_ns[lane], now + guard_lead_ns[lane] + limits.jitter_allowance_ns)
    dt_s = wp.max(wp.float64(credited_ns - guard_credited_ns[lane]) * limits.ns_to_s,
                  limits.period_s)
    allowed_m = limits.velocity_trip_m_per_s * dt_s
    allowed_m = allowed_m + limits.jump_margin_m
    jump_x = wp.abs(position[lane, 0] - handle_position[lane, 0])
    jump_y = wp.abs(position[lane, 1] - handle_position[lane, 1])
    step = limits.force_rate_limit_N_per_s * dt_s
    plain = (plain_axis(force[lane, 0], position[lane, 0], handle_force[lane, 0], step,
                        limits.position_min_x_m, limits.position_max_x_m, limits)
             and plain_axis(force[lane, 1], position[lane, 1], handle_force[lane, 1], step,
                            limits.position_min_y_m, limits.position_max_y_m, limits)
             and not (wp.max(jump_x, jump_y) > allowed_m))
    return plain, credited_ns


@wp.func
def tool_inside(lane: int, tool: wp.array2d(dtype=wp.float64),
                work_area_m: wp.array2d(dtype=wp.float64)) -> bool:
    """The tool's position (m) inside the lane's work area (x low, x high, y low, y high; m),
    edges included: the supervisor's work-area stop does not act."""
    x = tool[lane, 0]
    y = tool[lane, 2]
    return (work_area_m[lane, 0] <= x and x <= work_area_m[lane, 1]
            and work_area_m[lane, 2] <= y and y <= work_area_m[lane, 3])


@wp.func
def take_message(lane: int, now: wp.int64, credited_ns: wp.int64,
                 force: wp.array2d(dtype=wp.float64), position: wp.array2d(dtype=wp.float64),
                 epoch: wp.array(dtype=wp.int64), send_ns: wp.array(dtype=wp.int64),
                 scale: wp.array(dtype=wp.float64),
                 handle_force: wp.array2d(dtype=wp.float64),
                 handle_position: wp.array2d(dtype=wp.float64),
                 guard_epoch: wp.array(dtype=wp.int64),
                 guard_credited_ns: wp.array(dtype=wp.int64),
                 guard_received_ns: wp.array(dtype=wp.int64),
                 guard_lead_ns: wp.array(dtype=wp.int64), echo_send_ns: wp.array(dtype=wp.int64),
                 force_scale: wp.array(dtype=wp.float64), unseen: wp.array(dtype=wp.int64),
                 limits: GuardLimits):
    """A quiet lane's fresh message taken as the guard and :meth:`SendClock.accept` (the same
    epoch) take it, ``now`` and ``credited_ns`` the loop time and the credited send time
    (ns)."""
    handle_force[lane, 0] = force[lane, 0]
    handle_force[lane, 1] = force[lane, 1]
    handle_position[lane, 0] = position[lane, 0]
    handle_position[lane, 1] = position[lane, 1]
    guard_epoch[lane] = epoch[lane]
    guard_credited_ns[lane] = credited_ns
    # (an integer division truncates here and floors in Python: they differ only for a time
    # going back, where both keep the lead)
    lead_ns = guard_lead_ns[lane]
    risen_ns = lead_ns + (now - guard_received_ns[lane]) / limits.lead_rise_divisor
    guard_lead_ns[lane] = wp.max(lead_ns, wp.min(send_ns[lane] - now, risen_ns))
    guard_received_ns[lane] = now
    echo_send_ns[lane] = send_ns[lane]
    force_scale[lane] = scale[lane]
    unseen[lane] = unseen[lane] + wp.int64(1)


@wp.kernel
def quiet_kernel(
    fresh: wp.array(dtype=wp.bool),
    force: wp.array2d(dtype=wp.float64),
    position: wp.array2d(dtype=wp.float64),
    flags: wp.array(dtype=wp.int64),
    epoch: wp.array(dtype=wp.int64),
    send_ns: wp.array(dtype=wp.int64),
    scale: wp.array(dtype=wp.float64),
    silence_s: wp.array(dtype=wp.float64),
    guard_faulted: wp.array(dtype=wp.bool),
    guard_has_last: wp.array(dtype=wp.bool),
    steady: wp.array(dtype=wp.bool),
    max_age_s: wp.array(dtype=wp.float64),
    tool: wp.array2d(dtype=wp.float64),
    work_area_m: wp.array2d(dtype=wp.float64),
    now_ns: wp.array(dtype=wp.int64),
    limits: GuardLimits,
    handle_force: wp.array2d(dtype=wp.float64),
    handle_position: wp.array2d(dtype=wp.float64),
    guard_epoch: wp.array(dtype=wp.int64),
    guard_credited_ns: wp.array(dtype=wp.int64),
    guard_received_ns: wp.array(dtype=wp.int64),
    guard_lead_ns: wp.array(dtype=wp.int64),
    echo_send_ns: wp.array(dtype=wp.int64),
    force_scale: wp.array(dtype=wp.float64),
    unseen: wp.array(dtype=wp.int64),
    admitted: wp.array(dtype=wp.bool),
    quiet: wp.array(dtype=wp.bool),
    loud_count: wp.array(dtype=wp.int32),
):
    lane = wp.tid()
    came = fresh[lane]
    now = now_ns[0]
    plain = False
    credited_ns = wp.int64(0)
    if came and (not guard_faulted[lane]) and guard_has_last[lane] and (
            epoch[lane] == guard_epoch[lane]):
        plain, credited_ns = guard_takes_plain(lane, now, force, position, send_ns,
                                               handle_force, handle_position,
                                               guard_credited_ns, guard_lead_ns, limits)
    enabled = flags_quiet(flags[lane], limits.quiet_mask, limits.quiet_value)
    # the supervisor changes nothing (SlaveSupervisor.update returns NONE)
    still = (watchdog_stays_ok(steady[lane], silence_s[lane], max_age_s[lane])
             and tool_inside(lane, tool, work_area_m))
    is_quiet = still and ((not came) or (plain and enabled))
    quiet[lane] = is_quiet
    taken = is_quiet and came
    admitted[lane] = taken
    if taken:
        take_message(lane, now, credited_ns, force, position, epoch, send_ns, scale,
                     handle_force, handle_position, guard_epoch, guard_credited_ns,
                     guard_received_ns, guard_lead_ns, echo_send_ns, force_scale, unseen,
                     limits)
    count_loud(is_quiet, loud_count)


def guard_limits(settings: InputGuardSettings, period_s: float) -> Any:
    """The kernel's :class:`GuardLimits` for the guards' settings and the slave's Ts (s)."""
    limits = GuardLimits()
    limits.period_s = float(period_s)
    limits.ns_to_s = 1e-9
    limits.force_limit_N = float(settings.force_limit_N)
    limits.force_trip_N = float(settings.force_trip_N)
    limits.force_rate_limit_N_per_s = float(settings.force_rate_limit_N_per_s)
    limits.position_min_x_m, limits.position_min_y_m = map(float, settings.position_min_m)
    limits.position_max_x_m, limits.position_max_y_m = map(float, settings.position_max_m)
    limits.velocity_trip_m_per_s = float(settings.velocity_trip_m_per_s)
    limits.jump_margin_m = float(settings.jump_margin_m)
    limits.jitter_allowance_ns = settings.jitter_allowance_ns
    limits.lead_rise_divisor = LEAD_RISE_DIVISOR
    limits.quiet_mask = QUIET_MASK
    limits.quiet_value = QUIET_VALUE
    return limits


class QuietLanes:
    """The recorded launch over the slave's quiet-lane filter's and tick's persistent
    arrays (``views``: name -> numpy array, see :func:`quiet_kernel`); the tick's message
    columns are copied into buffers of its own, or read in place while a caller hands the
    very same arrays every tick (:class:`~haptic.common.runtime.replayed_launch.
    InPlaceInputs`). :meth:`run` returns the lanes that need their
    guard and supervisor."""

    def __init__(self, lanes: int, limits: Any, views: dict[str, np.ndarray]) -> None:
        f64, i64, flag = wp.float64, wp.int64, wp.bool
        self.fresh = np.zeros(lanes, bool)
        self.force_N = np.zeros((lanes, 2))
        self.position_m = np.zeros((lanes, 2))
        self.flags = np.zeros(lanes, np.int64)
        self.epoch = np.zeros(lanes, np.int64)
        self.send_time_ns = np.zeros(lanes, np.int64)
        self.force_scale = np.zeros(lanes)
        self.silence_s = np.zeros(lanes)
        self.now_ns = np.zeros(1, np.int64)
        self.quiet = np.zeros(lanes, bool)
        self.loud_count = np.zeros(1, np.int32)
        messages = [
            (self.fresh, flag), (self.force_N, f64), (self.position_m, f64),
            (self.flags, i64), (self.epoch, i64), (self.send_time_ns, i64),
            (self.force_scale, f64), (self.silence_s, f64)]
        held = [
            (views["guard_faulted"], flag), (views["guard_has_last"], flag),
            (views["steady"], flag), (views["max_age_s"], f64), (views["tool"], f64),
            (views["work_area_m"], f64), (self.now_ns, i64)]
        outputs = [
            (views["handle_force_N"], f64), (views["handle_position_m"], f64),
            (views["guard_epoch"], i64), (views["guard_credited_ns"], i64),
            (views["guard_received_ns"], i64), (views["guard_lead_ns"], i64),
            (views["echo_send_time_ns"], i64), (views["force_scale"], f64),
            (views["unseen"], i64), (views["admitted"], flag), (self.quiet, flag),
            (self.loud_count, wp.int32)]
        self._warp_arrays = [host_array(array, dtype) for array, dtype in held + outputs]
        held_arrays = self._warp_arrays[:len(held)]
        output_arrays = self._warp_arrays[len(held):]

        def record(message_arrays: list) -> ReplayedLaunch:
            return ReplayedLaunch(wp.launch(
                quiet_kernel, dim=lanes, device=DEVICE,
                inputs=[*message_arrays, *held_arrays, limits, *output_arrays],
                record_cmd=True))

        #: the tick's message columns: copied into these buffers (the integer ones as
        #: astype), or read in place while a caller hands the same arrays every tick (the
        #: lockstep's delay line)
        self.inputs = InPlaceInputs(
            [array for array, _ in messages], [kind for _, kind in messages],
            ("same_kind", "same_kind", "same_kind", "unsafe", "unsafe", "unsafe",
             "same_kind", "same_kind"), record)

    def run(self, now_ns: int, fresh: np.ndarray, force_N: np.ndarray, position_m: np.ndarray,
            flags: np.ndarray, epoch: np.ndarray, send_time_ns: np.ndarray,
            force_scale: np.ndarray, silence_s: np.ndarray) -> list[int]:
        """One tick's loop time (ns, :func:`~haptic.common.wire.send_clock.receive_time_ns`),
        messages (the handle line's columns) and silences (s): takes the quiet lanes'
        messages into the bound arrays and returns the other lanes, in order."""
        self.now_ns[0] = now_ns
        self.loud_count[0] = 0
        self.inputs.launch((fresh, force_N, position_m, flags, epoch, send_time_ns,
                            force_scale, silence_s))
        if not self.loud_count[0]:
            return []
        return np.flatnonzero(~self.quiet).tolist()


__all__ = ["QUIET_MASK", "QUIET_VALUE", "GuardLimits", "QuietLanes", "guard_limits",
           "quiet_kernel"]
