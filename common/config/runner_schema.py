"""The ``[runner]`` table's schema: how both programs pace their loop (plain data).

:mod:`haptic.common.runtime.runner_config` turns the validated table into
:class:`~haptic.common.runtime.runner_config.RunnerSettings`; common/runtime/realtime.py
explains each setting.
"""

from __future__ import annotations

import os

from haptic.common.config.fields import Field, Schema

#: Highest SCHED_FIFO priority Linux allows.
MAX_FIFO_PRIORITY = 99


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


def _switch_interval_check(value: float) -> str | None:
    if 0.0 < value < 1e-6:
        return f"must be 0 or at least 1e-6 s: Python counts it in whole us (got {value:g})"
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
    "other_threads_cpus": Field(
        "str", "CPUs of the program's other threads (Zenoh's, the display's), set before they "
        "start, e.g. \"0\"; empty for any.", check=_cpus_check,
    ),
    "gil_switch_interval_s": Field(
        "float", "Python's GIL switch interval while the loop runs, s: the longest the loop "
        "waits for the GIL held by another thread; 0 leaves it as it is (Python's default is "
        "5 ms).", minimum=0.0, maximum=0.1, check=_switch_interval_check,
    ),
    "cpu_latency_limit_us": Field(
        "int", "The CPUs' idle exit latency limit held while the loop runs (Linux PM QoS, "
        "/dev/cpu_dma_latency), us: 0 keeps idle CPUs polling, so a wake-up from another "
        "CPU is answered at once; -1 makes no request.", minimum=-1, maximum=10_000_000,
    ),
    "zenoh_thread_priority": Field(
        "int", "SCHED_FIFO priority of Zenoh's runtime threads, below realtime_priority; 0 "
        "leaves them with normal scheduling.", minimum=0, maximum=MAX_FIFO_PRIORITY,
    ),
    "zenoh_threads_batch": Field(
        "bool", "Zenoh's runtime threads in SCHED_BATCH beside a loop with normal "
        "scheduling (realtime_priority 0): their wake-ups never preempt a running thread (the "
        "loops, the emulated drives). Ignored with a SCHED_FIFO loop, which they cannot "
        "preempt anyway, and when zenoh_thread_priority puts them in SCHED_FIFO."),
    "display_backoff": Field(
        "bool", "The display thread's state and clay rates halve while the loop overruns "
        "more than 0.1 % of its ticks, down to a sixteenth, and come back after 2 s without."),
}
