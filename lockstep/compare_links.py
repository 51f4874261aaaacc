"""The two delay lines of a comparison run, one column per lane, each lane its own network.

The lines are lockstep/delay_line.py's: exact whole-sample delays with the link's loss and
jitter draws. A round trip of ``n`` samples is split ``d1 = n // 2`` on the handle line and
``d2 = n - d1`` on the tool line; the tool line has one structural sample more, because in a
tick the master steps before the slave has sent (the lockstep simulator's timing,
docs/lockstep.md). The lanes of a task with the same injection draw their schedules together
from a generator seeded by the run's seed, the task and the injection (:func:`draw_key`), so a
run is reproducible bit for bit and every control meets the same losses and jitter.
"""

from __future__ import annotations

import numpy as np

from haptic.lockstep.compare_grid import LOSS_MODELS, TASKS, Lane
from haptic.lockstep.delay_line import DelayLine, source_schedule

#: The handle line's and the tool line's structural samples.
HANDLE_OFFSET_SAMPLES = 0
TOOL_OFFSET_SAMPLES = 1


def round_trip_samples(lanes: list[Lane], period_s: float) -> np.ndarray:
    """Each lane's round trip in whole samples."""
    return np.array([int(round(lane.network.round_trip_s / period_s)) for lane in lanes],
                    np.int64)


def draw_key(lane: Lane) -> tuple[int, ...]:
    """What a lane's draws depend on besides the seed: its task, loss, loss model, jitter and
    whether it is a ladder rung (not its delay, nor which other lanes run beside it), so a
    cell's network gets the same draws under every control."""
    network = lane.network
    return (TASKS.index(lane.task), int(round(network.loss * 1e6)),
            LOSS_MODELS.index(network.loss_model), int(round(network.jitter_s * 1e9)),
            int(lane.ladder))


def lane_schedules(lanes: list[Lane], steps: int, period_s: float, seed: int
                   ) -> tuple[np.ndarray, np.ndarray]:
    """The handle line's and the tool line's source schedules (steps, lanes)."""
    samples = round_trip_samples(lanes, period_s)
    to_slave = samples // 2
    to_master = samples - to_slave
    handle = np.empty((steps, len(lanes)), np.int64)
    tool = np.empty((steps, len(lanes)), np.int64)
    groups: dict[tuple[int, ...], list[int]] = {}
    for index, lane in enumerate(lanes):
        groups.setdefault(draw_key(lane), []).append(index)
    for key, members in groups.items():
        columns = np.asarray(members)
        injection = lanes[members[0]].network.injection()
        rng_handle, rng_tool = np.random.default_rng([seed, *key]).spawn(2)
        handle[:, columns] = source_schedule(steps, to_slave[columns], HANDLE_OFFSET_SAMPLES,
                                             period_s, injection, rng_handle)
        tool[:, columns] = source_schedule(steps, to_master[columns], TOOL_OFFSET_SAMPLES,
                                           period_s, injection, rng_tool)
    return handle, tool


def lane_lines(lanes: list[Lane], steps: int, period_s: float, seed: int,
               handle_initial: np.ndarray, tool_initial: np.ndarray
               ) -> tuple[DelayLine, DelayLine]:
    """(handle line, tool line) over the lanes; ``*_initial`` (lanes, channels): what each
    side reads before the first message arrives."""
    handle, tool = lane_schedules(lanes, steps, period_s, seed)
    return (DelayLine(handle, handle_initial.shape[1], handle_initial, period_s=period_s),
            DelayLine(tool, tool_initial.shape[1], tool_initial, period_s=period_s))


__all__ = ["draw_key", "lane_lines", "lane_schedules", "round_trip_samples"]
