"""Wake-up benchmark: what this machine charges for one process waking another, the floor
under every hop of the programs' tick (the master's SYNC to the emulated drives and their
answer, each Zenoh message between the loops).

Two processes ping-pong one byte over a pair of pipes, each blocked in ``read`` between
messages: on two different CPUs (the wake-up crosses CPUs, as between the master and the slave
on two cores) and both on one CPU (a plain context switch). Per case: the round trip's p50 and
p99 (s) and the CPU time both processes used per one-way message, ``cpu_per_wakeup_s`` (their
user + system time / (2 x round trips)), back to back and paced at one round trip per Ts, as
the loops send. A one-way message costs at least ``round_trip / 2`` of latency and
``cpu_per_wakeup_s`` of CPU on the machine; a tick with n such hops needs n times that before
any of our code runs. Figures only; nothing is asserted.

Usage: ``python bench/wakeup_bench.py [--round-trips N] [--period S] [--json]``.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from typing import Any

import numpy as np

from haptic.common.runtime.machine import cpu_model
from haptic.common.runtime.realtime import cpu_latency_request

#: The child: pinned to its CPU, echo every byte until the pipe closes.
_ECHO = """
import os, sys
cpu, inbound, outbound = (int(a) for a in sys.argv[1:4])
if cpu >= 0:
    os.sched_setaffinity(0, {cpu})
os.write(outbound, b"r")
while os.read(inbound, 1):
    os.write(outbound, b"x")
"""


def _cpu_s(usage: resource.struct_rusage) -> float:
    return usage.ru_utime + usage.ru_stime


def ping_pong(parent_cpu: int, child_cpu: int, round_trips: int, warmup: int = 200,
              period_s: float = 0.0) -> dict[str, float]:
    """Round trips of one byte with a child process over two pipes, this process on
    ``parent_cpu`` and the child on ``child_cpu`` (-1: not pinned); one round trip every
    ``period_s`` s (0: back to back). Returns ``round_trip_p50_s``, ``round_trip_p99_s``,
    ``cpu_per_wakeup_s`` (both processes' CPU per one-way message, s) and ``round_trips``."""
    to_child_r, to_child_w = os.pipe()
    to_parent_r, to_parent_w = os.pipe()
    affinity = os.sched_getaffinity(0) if hasattr(os, "sched_getaffinity") else None
    child = subprocess.Popen(
        [sys.executable, "-c", _ECHO, str(child_cpu), str(to_child_r), str(to_parent_w)],
        pass_fds=(to_child_r, to_parent_w))
    os.close(to_child_r)
    os.close(to_parent_w)
    try:
        if parent_cpu >= 0:
            os.sched_setaffinity(0, {parent_cpu})
        if os.read(to_parent_r, 1) != b"r":
            raise RuntimeError("the echo process did not start")
        times = np.empty(round_trips)
        clock = time.perf_counter
        for _ in range(warmup):
            os.write(to_child_w, b"x")
            os.read(to_parent_r, 1)
        start_self = _cpu_s(resource.getrusage(resource.RUSAGE_SELF))
        with open(f"/proc/{child.pid}/stat", encoding="ascii") as stat:
            start_child = _proc_cpu_s(stat.read())
        next_ping = clock()
        for index in range(round_trips):
            if period_s > 0.0:
                next_ping += period_s
                wait = next_ping - clock()
                if wait > 0.0:
                    time.sleep(wait)
            sent = clock()
            os.write(to_child_w, b"x")
            os.read(to_parent_r, 1)
            times[index] = clock() - sent
        used_self = _cpu_s(resource.getrusage(resource.RUSAGE_SELF)) - start_self
        with open(f"/proc/{child.pid}/stat", encoding="ascii") as stat:
            used_child = _proc_cpu_s(stat.read()) - start_child
    finally:
        os.close(to_child_w)  # the child's read returns b"": it ends
        os.close(to_parent_r)
        try:
            child.wait(timeout=10.0)
        except subprocess.TimeoutExpired:
            child.kill()
            child.wait()
        if affinity is not None:
            os.sched_setaffinity(0, affinity)
    return {
        "round_trip_p50_s": float(np.percentile(times, 50)),
        "round_trip_p99_s": float(np.percentile(times, 99)),
        "cpu_per_wakeup_s": (used_self + used_child) / (2 * round_trips),
        "round_trips": round_trips,
    }


def _proc_cpu_s(stat: str) -> float:
    """User + system time (s) from a /proc/PID/stat line."""
    fields = stat.rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def measure(round_trips: int = 5000, period_s: float = 0.00054,
            cpu_latency_limit_us: int = 0) -> dict[str, Any]:
    """:func:`cases` with the idle states as they are (``as_is``) and, unless
    ``cpu_latency_limit_us`` is -1, under that CPU latency request (``requested``: the
    cases, or the refusal as ``warning``)."""
    cpus = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else []
    result: dict[str, Any] = {"cpu_model": cpu_model(), "cpus": len(cpus) or os.cpu_count(),
                              "period_s": period_s, "as_is": cases(round_trips, period_s)}
    if cpu_latency_limit_us >= 0:
        with cpu_latency_request(cpu_latency_limit_us) as (held_us, warning):
            result["requested"] = ({"cpu_latency_limit_us": held_us,
                                    **cases(round_trips, period_s)}
                                   if held_us is not None else {"warning": warning})
    return result


def cases(round_trips: int, period_s: float) -> dict[str, Any]:
    """Every case on this machine now: ``cross_cpu`` and ``same_cpu`` back to back,
    ``cross_cpu_paced`` and ``same_cpu_paced`` one round trip per ``period_s``; the cross-CPU
    cases only where this process may run on two CPUs."""
    cpus = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else []
    result: dict[str, Any] = {}
    paced = max(200, min(round_trips, int(1.0 / period_s)))  # about a second paced
    if len(cpus) >= 2:
        result["cross_cpu"] = {"cpus": cpus[:2], **ping_pong(cpus[0], cpus[1], round_trips)}
        result["cross_cpu_paced"] = {"cpus": cpus[:2], **ping_pong(cpus[0], cpus[1], paced,
                                                                    period_s=period_s)}
    first = cpus[0] if cpus else -1
    result["same_cpu"] = {"cpus": [first], **ping_pong(first, first, round_trips)}
    result["same_cpu_paced"] = {"cpus": [first], **ping_pong(first, first, paced,
                                                             period_s=period_s)}
    return result


def format_result(result: dict[str, Any]) -> list[str]:
    """The table's lines."""
    lines = [f"wake-up cost on {result['cpu_model']} ({result['cpus']} CPUs): one byte "
             "ping-ponged between two processes over pipes"]
    requested = result.get("requested")
    sets = [("idle states as they are", result["as_is"])]
    if requested is not None and "warning" in requested:
        lines.append(f"  (no CPU latency request: {requested['warning']})")
    elif requested is not None:
        sets.append((f"CPU latency limit {requested['cpu_latency_limit_us']} us held",
                     requested))
    for title, measured in sets:
        lines.append(f" {title}:")
        lines.extend(_case_lines(measured, result["period_s"]))
    return lines


def _case_lines(result: dict[str, Any], period_s: float) -> list[str]:
    lines = []
    for name, label in (("cross_cpu", "two CPUs, back to back"),
                        ("cross_cpu_paced", f"two CPUs, one per {period_s * 1e3:g} ms"),
                        ("same_cpu", "one CPU, back to back"),
                        ("same_cpu_paced", f"one CPU, one per {period_s * 1e3:g} ms")):
        case = result.get(name)
        if case is None:
            continue
        lines.append(f"  {label:28s} round trip p50 {case['round_trip_p50_s'] * 1e6:7.1f} us "
                     f"p99 {case['round_trip_p99_s'] * 1e6:7.1f} us  CPU per wake-up "
                     f"{case['cpu_per_wakeup_s'] * 1e6:5.1f} us")
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.split("\n\n")[0])
    parser.add_argument("--round-trips", type=int, default=5000,
                        help="round trips back to back per case (default 5000)")
    parser.add_argument("--period", type=float, default=0.00054,
                        help="the paced cases' period, s (default Ts = 0.00054)")
    parser.add_argument("--cpu-latency-us", type=int, default=0, metavar="US",
                        help="also measure under this CPU latency request, us (default 0, "
                        "the programs' default; -1: only as they are)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args(argv)
    if args.round_trips < 1 or not args.period > 0.0 or args.cpu_latency_us < -1:
        parser.error("--round-trips must be >= 1, --period > 0 and --cpu-latency-us >= -1")
    result = measure(args.round_trips, args.period, args.cpu_latency_us)
    if args.json:
        print(json.dumps(result))
    else:
        print("\n".join(format_result(result)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
