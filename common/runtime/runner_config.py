"""Configuration of the real-time runner: the ``[runner]`` TOML table.

Both programs pace their loop with :class:`~haptic.common.runtime.runner.RealTimeRunner`; this table
says how (common/runtime/realtime.py explains each setting)::

    [runner]
    spin_s = 0.0001          # spin this long before each tick, s
    realtime_priority = 40   # SCHED_FIFO priority of the loop thread, 0 = normal (default)
    tight_timers = true      # timer slack 1 ns on the loop thread
    loop_cpus = ""           # CPUs of the loop thread, e.g. "1" or "0,1"; empty = any
    other_threads_cpus = ""  # CPUs of the program's other threads (Zenoh, display); empty = any
    gil_switch_interval_s = 0.0002  # Python's GIL switch interval while the loop runs, s (0: as is)
    cpu_latency_limit_us = 0  # idle CPUs' exit latency limit held for the run, us; -1: none
    zenoh_thread_priority = 0  # SCHED_FIFO priority of Zenoh's threads (below the loop's); 0: off
    zenoh_threads_batch = true  # Zenoh's threads in SCHED_BATCH beside a normal (not FIFO) loop
    display_backoff = true   # the display's rates back off while the loop overruns
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from haptic.common.config import ConfigError
from haptic.common.config.runner_schema import parse_cpus
from haptic.common.runtime.realtime import (
    RealtimeSettings,
    batch_threads,
    place_process_threads,
    raise_threads,
)


@dataclass(frozen=True)
class RunnerSettings:
    """The validated ``[runner]`` table: ``spin_s`` in s and the loop thread's scheduling."""

    spin_s: float
    realtime: RealtimeSettings
    zenoh_thread_priority: int = 0
    #: Zenoh's threads in SCHED_BATCH when ``zenoh_thread_priority`` and the loop's
    #: ``realtime_priority`` are 0
    zenoh_threads_batch: bool = True
    other_threads_cpus: tuple[int, ...] = ()
    #: the display thread's rates back off while the loop overruns (display_backoff.py)
    display_backoff: bool = True


def runner_settings_from(config: dict[str, Any]) -> RunnerSettings:
    """The :class:`RunnerSettings` of a validated configuration."""
    table = config["runner"]
    zenoh_priority = int(table["zenoh_thread_priority"])
    loop_priority = int(table["realtime_priority"])
    if zenoh_priority and loop_priority and zenoh_priority >= loop_priority:
        raise ConfigError("runner.zenoh_thread_priority",
                          f"must be below runner.realtime_priority ({loop_priority}), or the "
                          f"network threads preempt the loop (got {zenoh_priority})")
    cpu_sets = {}
    for key in ("loop_cpus", "other_threads_cpus"):
        try:
            cpu_sets[key] = parse_cpus(table[key])
        except ValueError as error:
            raise ConfigError(f"runner.{key}", str(error)) from None
    if cpu_sets["other_threads_cpus"] and not cpu_sets["loop_cpus"]:
        raise ConfigError("runner.other_threads_cpus",
                          "needs runner.loop_cpus too: the loop runs on the main thread, which "
                          "would otherwise stay on the other threads' CPUs")
    return RunnerSettings(
        spin_s=float(table["spin_s"]),
        realtime=RealtimeSettings(
            priority=int(table["realtime_priority"]),
            tight_timers=bool(table["tight_timers"]),
            cpus=cpu_sets["loop_cpus"],
            gil_switch_interval_s=float(table["gil_switch_interval_s"]),
            cpu_latency_limit_us=int(table["cpu_latency_limit_us"]),
        ),
        zenoh_thread_priority=int(table["zenoh_thread_priority"]),
        zenoh_threads_batch=bool(table["zenoh_threads_batch"]),
        other_threads_cpus=cpu_sets["other_threads_cpus"],
        display_backoff=bool(table["display_backoff"]),
    )


def place_other_threads(settings: RunnerSettings) -> dict[str, object]:
    """Apply ``other_threads_cpus`` to the calling (main) thread, so the threads the program
    starts next (Zenoh's, the display's) inherit it; call it before the link opens. Returns
    the run summary's keys (empty when the setting is empty)."""
    if not settings.other_threads_cpus:
        return {}
    cpus, warnings = place_process_threads(settings.other_threads_cpus)
    return {"other_threads_cpus": list(cpus) if cpus is not None else None,
            "other_threads_warnings": warnings}


def prioritise_zenoh_threads(settings: RunnerSettings) -> dict[str, object]:
    """Apply ``zenoh_thread_priority``, else ``zenoh_threads_batch`` where the loop is not
    configured for SCHED_FIFO (call it once the link is up: Zenoh starts its receive threads
    with the first connection; threads they start later inherit it). Returns the run
    summary's keys (empty when nothing changes)."""
    priority = settings.zenoh_thread_priority
    if not priority:
        # a SCHED_FIFO loop is never preempted by them anyway: batching would only delay
        # one Zenoh thread behind another (the link's p50 rose in loop_bench's layouts)
        if not settings.zenoh_threads_batch or settings.realtime.priority > 0:
            return {}
        changed, warnings = batch_threads()
        return {"zenoh_threads_batch": True, "zenoh_threads_batched": changed,
                "zenoh_thread_warnings": warnings}
    changed, warnings = raise_threads(priority)
    return {"zenoh_thread_priority": priority, "zenoh_threads_raised": changed,
            "zenoh_thread_warnings": warnings}
