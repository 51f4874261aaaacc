"""What machine a figure was taken on: the CPU's model name, for the benchmarks' reports
(figures from different machines are compared by it), how many CPUs this process may use, and
the CPU time another process of this host has used."""

from __future__ import annotations

import os
import platform


def cpu_model() -> str:
    """The CPU's model name (/proc/cpuinfo), or the platform's processor string."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as cpuinfo:
            for line in cpuinfo:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def usable_cpus() -> list[int]:
    """The CPUs this process may run on, in order (its affinity where the OS tells, else all
    of them)."""
    try:
        return sorted(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return list(range(os.cpu_count() or 1))


def usable_cpu_count() -> int:
    """How many CPUs this process may run on (:func:`usable_cpus`)."""
    return len(usable_cpus())


def process_cpu_s(pid: int) -> float | None:
    """User + system CPU time process ``pid`` has used so far, s (Linux /proc; None elsewhere
    or when it is gone). Clock-tick resolution (10 ms): compare readings seconds apart."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii") as file:
            fields = file.read().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return None
