"""NVIDIA Warp kernel of the lockstep's quiet lanes on the master side
(lockstep/quiet_lanes.py, ``MasterQuietLanes``): for every lane in one launch, the
tick's tool message stored where one came, and whether the lane's supervisor would change
anything.

A lane is quiet when its :class:`~haptic.master.supervisor.MasterSupervisor` would change
nothing but its stored message and return ``NONE``: :meth:`MasterSupervisor.steady`, the
watchdog not silent (the silence not above the supervisor's ``max_age_s``) and the newest
tool message (the fresh one where a message came) carrying FORCES_ENABLED without
WORK_AREA_STOP; the slave alive and no hardware fault are the caller's to ensure. Mirrors
:meth:`MasterSupervisor.update` line by line, with the rules the slave's kernel shares
(common/runtime/quiet_rules.py); tests/lockstep/test_quiet_lanes.py runs every
lane through both, bit for bit. One launch replaces about 15 numpy calls a tick.
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np
import warp as wp

from haptic.common.runtime.quiet_rules import count_loud, flags_quiet, watchdog_stays_ok
from haptic.common.runtime.replayed_launch import InPlaceInputs, ReplayedLaunch, host_array
from haptic.common.wire.messages import Flags

# The programs print JSON on stdout: Warp must not announce itself there.
wp.config.log_level = wp.LOG_WARNING

DEVICE = "cpu"
#: The flag bits that decide a quiet lane, and the value they must have (a slave's last
#: message, ``STOPPING``, goes through the supervisor).
QUIET_MASK = int(Flags.FORCES_ENABLED) | int(Flags.WORK_AREA_STOP) | int(Flags.STOPPING)
QUIET_VALUE = int(Flags.FORCES_ENABLED)


@functools.cache
def quiet_kernel(columns: int) -> Any:
    """The quiet-lane kernel for message rows of ``columns`` columns (the copy of a fresh
    message unrolled: a loop over an array's shape runs about twice as long on Warp's CPU
    device). One Warp module per column count."""

    @wp.kernel(module=f"{__name__}.quiet_{columns}")
    def quiet(
        fresh: wp.array(dtype=wp.bool),
        flags: wp.array(dtype=wp.int64),
        rows: wp.array2d(dtype=wp.float64),
        force: wp.array2d(dtype=wp.float64),
        silence_s: wp.array(dtype=wp.float64),
        steady: wp.array(dtype=wp.bool),
        max_age_s: wp.array(dtype=wp.float64),
        quiet_mask: wp.int64,
        quiet_value: wp.int64,
        newest_flags: wp.array(dtype=wp.int64),
        newest_rows: wp.array2d(dtype=wp.float64),
        tool_force: wp.array2d(dtype=wp.float64),
        stale: wp.array(dtype=wp.bool),
        fed: wp.array(dtype=wp.bool),
        loud_count: wp.array(dtype=wp.int32),
    ):
        lane = wp.tid()
        came = fresh[lane]
        if came:
            newest_flags[lane] = flags[lane]
            for column in range(columns):
                newest_rows[lane, column] = rows[lane, column]
            tool_force[lane, 0] = force[lane, 0]
            tool_force[lane, 1] = force[lane, 1]
        quiet = (watchdog_stays_ok(steady[lane], silence_s[lane], max_age_s[lane])
                 and flags_quiet(newest_flags[lane], quiet_mask, quiet_value))
        if came and quiet:
            stale[lane] = True
        fed[lane] = not quiet
        count_loud(quiet, loud_count)

    return quiet


class QuietLanes:
    """The recorded launch over the master's quiet-lane filter's arrays
    (``views``: name -> numpy array, see :func:`quiet_kernel`); the tick's message columns
    are copied into buffers of its own, or read in place while a caller hands the very same
    arrays every tick (:class:`~haptic.common.runtime.replayed_launch.InPlaceInputs`)."""

    def __init__(self, lanes: int, views: dict[str, np.ndarray]) -> None:
        f64, i64, flag = wp.float64, wp.int64, wp.bool
        self.fresh = np.zeros(lanes, bool)
        self.flags = np.zeros(lanes, np.int64)
        self.rows = np.zeros_like(views["newest_rows"])
        self.force_N = np.zeros((lanes, 2))
        self.silence_s = np.zeros(lanes)
        self.fed = np.zeros(lanes, bool)
        self.loud_count = np.zeros(1, np.int32)

        held = [host_array(array, dtype) for array, dtype in (
            (views["steady"], flag), (views["max_age_s"], f64))]
        outputs = [host_array(array, dtype) for array, dtype in (
            (views["newest_flags"], i64), (views["newest_rows"], f64),
            (views["tool_force_N"], f64), (views["stale"], flag), (self.fed, flag),
            (self.loud_count, wp.int32))]
        self._warp_arrays = [*held, *outputs]  # they own nothing: views of the above
        kernel = quiet_kernel(self.rows.shape[1])

        def record(messages: list) -> ReplayedLaunch:
            return ReplayedLaunch(wp.launch(
                kernel, dim=lanes, device=DEVICE,
                inputs=[*messages, *held, QUIET_MASK, QUIET_VALUE, *outputs], record_cmd=True))

        #: the tick's message columns: copied into these buffers, or read in place while a
        #: caller hands the same arrays every tick (the lockstep's delay line)
        self.inputs = InPlaceInputs(
            (self.fresh, self.flags, self.rows, self.force_N, self.silence_s),
            (flag, i64, f64, f64, f64), ("same_kind", "unsafe", "same_kind", "same_kind",
                                         "same_kind"), record)

    def run(self, fresh: np.ndarray, flags: np.ndarray, rows: np.ndarray,
            force_N: np.ndarray, silence_s: np.ndarray) -> np.ndarray | None:
        """One tick's messages (the tool line's fresh, flags, rows and force) and silences
        (s): stores the fresh messages and returns the lanes fed to their supervisor
        ((lanes,) bool, valid until the next run), or None when every lane is quiet."""
        if rows.shape != self.rows.shape:
            raise ValueError("quiet lanes: the rows must have the shape of the stored rows")
        self.loud_count[0] = 0
        self.inputs.launch((fresh, flags, rows, force_N, silence_s))  # flags: as astype
        return self.fed if self.loud_count[0] else None


__all__ = ["QUIET_MASK", "QUIET_VALUE", "QuietLanes", "quiet_kernel"]
