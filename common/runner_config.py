"""Configuration of the real-time runner: the ``[runner]`` TOML table.

Both programs pace their loop with :class:`~haptic.common.runner.RealTimeRunner`; this table
says how (common/realtime.py explains each setting)::

    [runner]
    spin_s = 0.0001          # spin this long before each tick, s
    realtime_priority = 40   # SCHED_FIFO priority of the loop thread, 0 = normal (default)
    tight_timers = true      # timer slack 1 ns on the loop thread
    loop_cpus = ""           # CPUs of the loop thread, e.g. "1" or "0,1"; empty = any
    zenoh_thread_priority = 0  # SCHED_FIFO priority of Zenoh's threads (below the loop's); 0: off
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

from haptic.common.config import ConfigError, Field, Schema
from haptic.common.realtime import MAX_FIFO_PRIORITY, RealtimeSettings, raise_threads


def parse_cpus(text: str) -> tuple[int, ...]:
    """``"0,2-3"`` -> ``(0, 2, 3)``; empty text -> ``()``. Raises ValueError."""
    cpus: set[int] = set()
    for part in (p.strip() for p in text.split(",")):
        if not part:
            continue
        first, dash, last = part.partition("-")
        low, high = int(first), int(last) if dash else int(first)
        if low < 0 or high < low:
            raise ValueError(f"{part!r} is not a CPU index or range")
        cpus.update(range(low, high + 1))
    return tuple(sorted(cpus))


def _cpus_check(text: str) -> str | None:
    try:
        cpus = parse_cpus(text)
    except ValueError as error:
        return f"must list CPU indices like \"1\" or \"0,2-3\" ({error})"
    count = os.cpu_count()
    if count is not None and any(cpu >= count for cpu in cpus):
        return f"names a CPU this machine does not have (it has {count}: 0..{count - 1})"
    return None


RUNNER_SCHEMA: Schema = {
    "spin_s": Field(
        "float", "Spin on the clock this long before each tick's deadline (sleep before), s.",
        minimum=0.0, maximum=0.01,
    ),
    "realtime_priority": Field(
        "int", "SCHED_FIFO priority of the loop thread, 1..99; 0 for normal scheduling.",
        minimum=0, maximum=MAX_FIFO_PRIORITY,
    ),
    "tight_timers": Field("bool", "Timer slack of 1 ns on the loop thread (Linux)."),
    "loop_cpus": Field(
        "str", "CPUs the loop thread may run on, e.g. \"1\" or \"0,2-3\"; empty for any.",
        check=_cpus_check,
    ),
    "zenoh_thread_priority": Field(
        "int", "SCHED_FIFO priority of Zenoh's runtime threads, below realtime_priority; 0 "
        "leaves them with normal scheduling.", minimum=0, maximum=MAX_FIFO_PRIORITY,
    ),
}


@dataclass(frozen=True)
class RunnerSettings:
    """The validated ``[runner]`` table: ``spin_s`` in s and the loop thread's scheduling."""

    spin_s: float
    realtime: RealtimeSettings
    zenoh_thread_priority: int = 0


def runner_settings_from(config: dict[str, Any]) -> RunnerSettings:
    """The :class:`RunnerSettings` of a validated configuration."""
    table = config["runner"]
    zenoh_priority = int(table["zenoh_thread_priority"])
    loop_priority = int(table["realtime_priority"])
    if zenoh_priority and loop_priority and zenoh_priority >= loop_priority:
        raise ConfigError("runner.zenoh_thread_priority",
                          f"must be below runner.realtime_priority ({loop_priority}), or the "
                          f"network threads preempt the loop (got {zenoh_priority})")
    try:
        cpus = parse_cpus(table["loop_cpus"])
    except ValueError as error:
        raise ConfigError("runner.loop_cpus", str(error)) from None
    return RunnerSettings(
        spin_s=float(table["spin_s"]),
        realtime=RealtimeSettings(
            priority=int(table["realtime_priority"]),
            tight_timers=bool(table["tight_timers"]),
            cpus=cpus,
        ),
        zenoh_thread_priority=int(table["zenoh_thread_priority"]),
    )


def prioritise_zenoh_threads(settings: RunnerSettings) -> dict[str, object]:
    """Apply ``zenoh_thread_priority`` (call it once the link is up: Zenoh starts its receive
    threads with the first connection). Returns the run summary's keys (empty when off)."""
    priority = settings.zenoh_thread_priority
    if not priority:
        return {}
    changed, warnings = raise_threads(priority)
    return {"zenoh_thread_priority": priority, "zenoh_threads_raised": changed,
            "zenoh_thread_warnings": warnings}
