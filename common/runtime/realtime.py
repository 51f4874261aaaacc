"""Operating-system scheduling of a real-time loop thread: tight timers, SCHED_FIFO, CPUs,
and the CPUs' idle states.

The control loop sleeps for most of each period and spins only for the last ``spin_s``. How
long it must spin is set by how late a sleep wakes up, and that is set by the OS:

- Linux delays a normal thread's timer by its *timer slack* (50 us by default) so that it can
  batch wake-ups. :attr:`RealtimeSettings.tight_timers` sets the loop thread's slack to 1 ns
  (``PR_SET_TIMERSLACK``): a sleep then wakes microseconds late instead of the slack's tens,
  and the spin can shrink from 0.3 ms to 0.1 ms of the 0.54 ms period (bench/wakeup_bench.py
  measures the wake-ups). The loop's busy-waiting is what starves Zenoh's receive threads on a small
  machine, so this is also what keeps the link's delay near Zenoh's own.
- :attr:`RealtimeSettings.priority` > 0 puts the loop thread in ``SCHED_FIFO`` at that
  priority: it preempts every normal thread when its sleep ends (the ros2_control default is
  50). It needs ``CAP_SYS_NICE`` (root, or ``LimitRTPRIO`` in the systemd unit, or an
  ``rtprio`` line in ``/etc/security/limits.conf``). Refused, the loop runs with normal
  scheduling and the refusal is reported, never raised. The kernel's RT throttling
  (``/proc/sys/kernel/sched_rt_runtime_us``) still leaves other threads 5 % of each CPU should
  the loop never sleep.
- :attr:`RealtimeSettings.cpus` pins the loop thread to those CPUs (empty: any). With
  :func:`place_process_threads` a program first puts its other threads (Zenoh's, the
  display's: they inherit the main thread's CPUs when they start) on other CPUs, so that
  neither waits for the other: on 2 CPUs, both programs' loops on one (kept apart in time by
  the slave's phase lock, common/wire/phase_lock.py) and everything else on the other cut the
  link's one-way delay, its p99 most (bench/loop_bench.py; the layouts in docs/link.md section 9,
  the runs in docs/measurements/loop_bench.md).
- :attr:`RealtimeSettings.gil_switch_interval_s` shortens Python's GIL switch interval
  (5 ms by default) while the loop runs: a loop that wants the GIL back from another thread
  of the process (the display's JSON encoding) then waits at most about this long. 0 leaves
  the interval as it is.
- :attr:`RealtimeSettings.cpu_latency_limit_us` (>= 0) holds a Linux PM QoS request on
  ``/dev/cpu_dma_latency`` for the run, as ``cyclictest`` does: an idle CPU may only enter
  idle states that it leaves within that many us, so with 0 it polls instead of halting. Each
  hop of the tick (the master's SYNC to the drives and their answer, every Zenoh message)
  wakes a process on another CPU, and waking a halted CPU is what costs most on a virtual
  machine (haltpoll idle with ``guest_halt_poll_ns=0``): there the request cuts a cross-CPU
  wake-up roughly tenfold (``bench/wakeup_bench.py``) and the loops' overruns with it
  (``bench/loop_bench.py``; docs/link.md 6.2, figures in docs/measurements/link.md). The
  request is system-wide and ends when the file is closed (on exit, also a crash). It needs
  write access to the device (root, or a udev rule as in deploy/README.md); refused, the run
  goes on with the idle states as they are and the refusal is reported. -1 makes no request.

Everything but the CPU latency request applies to the *calling thread* only (on Linux, pid 0
means the calling thread for these calls), so the Zenoh and CAN threads a program started
before keep normal scheduling. Threads the loop thread starts later inherit it.
:class:`LoopThreadScheduling` restores the previous settings on exit.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import os
import struct
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

from haptic.common.config.runner_schema import MAX_FIFO_PRIORITY

#: ``prctl`` options (linux/prctl.h).
PR_SET_TIMERSLACK = 29
PR_GET_TIMERSLACK = 30
#: The timer slack of tight timers, ns (0 would mean "back to the default" to the kernel).
TIGHT_TIMER_SLACK_NS = 1
#: Linux's PM QoS CPU latency device: a request (a native int, us) holds while it is open.
CPU_LATENCY_DEVICE = "/dev/cpu_dma_latency"


@dataclass(frozen=True)
class RealtimeSettings:
    """How the loop thread is scheduled.

    ``priority``: SCHED_FIFO priority 1..99 of the loop thread, 0 for normal scheduling;
    ``tight_timers``: set the thread's timer slack to 1 ns; ``cpus``: CPU indices the loop
    thread may run on (empty: any); ``gil_switch_interval_s``: Python's GIL switch interval
    while the loop runs, s (0: left as it is; a process-wide setting);
    ``cpu_latency_limit_us``: the CPUs' idle exit latency limit held for the run, us (a
    system-wide PM QoS request; 0: idle CPUs poll; -1: no request).
    """

    priority: int = 0
    tight_timers: bool = True
    cpus: tuple[int, ...] = ()
    gil_switch_interval_s: float = 0.0
    cpu_latency_limit_us: int = -1

    def __post_init__(self) -> None:
        if not 0 <= self.priority <= MAX_FIFO_PRIORITY:
            raise ValueError(f"priority must be 0..{MAX_FIFO_PRIORITY} (got {self.priority})")
        if not self.gil_switch_interval_s >= 0.0:
            raise ValueError(
                f"gil_switch_interval_s must be >= 0 (got {self.gil_switch_interval_s})")
        if any(cpu < 0 for cpu in self.cpus):
            raise ValueError(f"cpus must be CPU indices >= 0 (got {self.cpus})")
        if self.cpu_latency_limit_us < -1:
            raise ValueError("cpu_latency_limit_us must be -1 (no request) or >= 0 us "
                             f"(got {self.cpu_latency_limit_us})")


@dataclass
class AppliedScheduling:
    """What the loop thread really got. ``policy`` is ``SCHED_FIFO`` or ``SCHED_OTHER``,
    ``priority`` its priority (0 for SCHED_OTHER), ``timer_slack_ns`` the thread's timer slack
    in ns (None where it cannot be read), ``cpus`` the CPUs it may run on (None: unknown);
    ``cpu_latency_limit_us`` the CPU latency limit held for the run, us (None: no request
    held); ``warnings``: each setting that was refused, and why."""

    policy: str = "SCHED_OTHER"
    priority: int = 0
    timer_slack_ns: int | None = None
    cpus: tuple[int, ...] | None = None
    warnings: list[str] = field(default_factory=list)
    gil_switch_interval_s: float | None = None
    cpu_latency_limit_us: int | None = None

    def describe(self) -> str:
        """One line, e.g. ``SCHED_FIFO 40, timer slack 1 ns, CPUs 0,1``."""
        parts = [f"{self.policy} {self.priority}" if self.policy == "SCHED_FIFO"
                 else self.policy]
        if self.timer_slack_ns is not None:
            parts.append(f"timer slack {self.timer_slack_ns} ns")
        if self.cpus is not None:
            parts.append("CPUs " + ",".join(str(c) for c in self.cpus))
        if self.cpu_latency_limit_us is not None:
            parts.append(f"CPU latency limit {self.cpu_latency_limit_us} us")
        return ", ".join(parts)

    def as_summary(self) -> dict[str, object]:
        """The run summary's ``scheduling*`` keys."""
        return {
            "scheduling": self.describe(),
            "scheduling_policy": self.policy,
            "scheduling_priority": self.priority,
            "timer_slack_ns": self.timer_slack_ns,
            "gil_switch_interval_s": self.gil_switch_interval_s,
            "cpu_latency_limit_us": self.cpu_latency_limit_us,
            "scheduling_warnings": list(self.warnings),
        }


def _libc_prctl() -> Callable[..., int] | None:
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True)
    except OSError:
        return None
    prctl = libc.prctl
    prctl.restype = ctypes.c_int
    prctl.argtypes = [ctypes.c_int, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong,
                      ctypes.c_ulong]
    return prctl


class OsScheduling:
    """The calls :class:`LoopThreadScheduling` makes, on the calling thread. Tests replace
    them; every method raises ``OSError`` (or returns None where unsupported)."""

    def __init__(self) -> None:
        self._prctl = _libc_prctl()

    def get_timer_slack_ns(self) -> int | None:
        if self._prctl is None:
            return None
        value = self._prctl(PR_GET_TIMERSLACK, 0, 0, 0, 0)
        return None if value < 0 else int(value)

    def set_timer_slack_ns(self, slack_ns: int) -> None:
        if self._prctl is None:
            raise OSError("timer slack is a Linux setting")
        if self._prctl(PR_SET_TIMERSLACK, slack_ns, 0, 0, 0) != 0:
            errno = ctypes.get_errno()
            raise OSError(errno, os.strerror(errno))

    def get_scheduler(self) -> tuple[int, int]:
        """``(policy, priority)`` of the calling thread."""
        return os.sched_getscheduler(0), os.sched_getparam(0).sched_priority

    def set_scheduler(self, policy: int, priority: int) -> None:
        os.sched_setscheduler(0, policy, os.sched_param(priority))

    def set_thread_scheduler(self, thread_id: int, policy: int, priority: int) -> None:
        """Another thread of this process, by its kernel thread id."""
        os.sched_setscheduler(thread_id, policy, os.sched_param(priority))

    def get_affinity(self) -> set[int] | None:
        return set(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None

    def set_affinity(self, cpus: set[int]) -> None:
        if not hasattr(os, "sched_setaffinity"):
            raise OSError("CPU affinity is not supported on this platform")
        os.sched_setaffinity(0, cpus)

    def request_cpu_latency(self, limit_us: int) -> int:
        """Open the PM QoS device and write ``limit_us``; returns the open file descriptor
        (the request holds until it is closed)."""
        if not sys.platform.startswith("linux"):
            raise OSError("the CPU latency request is a Linux setting")
        fd = os.open(CPU_LATENCY_DEVICE, os.O_WRONLY | os.O_CLOEXEC)
        try:
            os.write(fd, struct.pack("i", limit_us))
        except OSError:
            os.close(fd)
            raise
        return fd

    def release_cpu_latency(self, fd: int) -> None:
        os.close(fd)


class LoopThreadScheduling:
    """Context manager: apply ``settings`` to the calling thread on entry (each refusal is a
    warning in :attr:`applied`, never an exception) and restore what was there on exit."""

    def __init__(self, settings: RealtimeSettings, os_calls: OsScheduling | None = None) -> None:
        self.settings = settings
        self._os = os_calls if os_calls is not None else OsScheduling()
        self.applied = AppliedScheduling()
        self._previous_slack: int | None = None
        self._previous_scheduler: tuple[int, int] | None = None
        self._previous_affinity: set[int] | None = None
        self._previous_switch_interval_s: float | None = None
        self._cpu_latency: contextlib.ExitStack | None = None

    def __enter__(self) -> AppliedScheduling:
        s, calls, applied = self.settings, self._os, self.applied
        if s.tight_timers:
            try:
                self._previous_slack = calls.get_timer_slack_ns()
                calls.set_timer_slack_ns(TIGHT_TIMER_SLACK_NS)
            except (OSError, AttributeError) as error:
                self._previous_slack = None
                applied.warnings.append(f"tight timers refused: {error}")
        if s.cpus:
            try:
                self._previous_affinity = calls.get_affinity()
                calls.set_affinity(set(s.cpus))
            except (OSError, ValueError, AttributeError) as error:
                self._previous_affinity = None
                applied.warnings.append(f"CPU affinity {list(s.cpus)} refused: {error}")
        if s.priority > 0:
            try:
                self._previous_scheduler = calls.get_scheduler()
                calls.set_scheduler(os.SCHED_FIFO, s.priority)
            except (OSError, AttributeError) as error:
                self._previous_scheduler = None
                applied.warnings.append(
                    f"SCHED_FIFO {s.priority} refused ({error}): normal scheduling")
        if s.gil_switch_interval_s > 0.0:
            self._previous_switch_interval_s = sys.getswitchinterval()
            sys.setswitchinterval(s.gil_switch_interval_s)
        if s.cpu_latency_limit_us >= 0:
            self._cpu_latency = contextlib.ExitStack()
            held, warning = self._cpu_latency.enter_context(
                cpu_latency_request(s.cpu_latency_limit_us, calls))
            applied.cpu_latency_limit_us = held
            if warning is not None:
                applied.warnings.append(warning)
        self._read_back()
        return applied

    def _read_back(self) -> None:
        applied, calls = self.applied, self._os
        try:
            policy, priority = calls.get_scheduler()
            applied.policy = "SCHED_FIFO" if policy == getattr(os, "SCHED_FIFO", -1) else (
                "SCHED_RR" if policy == getattr(os, "SCHED_RR", -1) else "SCHED_OTHER")
            applied.priority = priority
        except (OSError, AttributeError):
            pass
        try:
            applied.timer_slack_ns = calls.get_timer_slack_ns()
        except OSError:
            applied.timer_slack_ns = None
        try:
            cpus = calls.get_affinity()
            applied.cpus = None if cpus is None else tuple(sorted(cpus))
        except OSError:
            applied.cpus = None
        applied.gil_switch_interval_s = sys.getswitchinterval()

    def __exit__(self, *_exc: object) -> None:
        calls = self._os
        # each restore on its own: one that fails must not keep the others from running
        if self._cpu_latency is not None:
            self._cpu_latency.close()  # the request released (a failed release is ignored)
            self._cpu_latency = None
        if self._previous_switch_interval_s is not None:
            try:
                sys.setswitchinterval(self._previous_switch_interval_s)
            except ValueError:
                pass
            self._previous_switch_interval_s = None
        if self._previous_scheduler is not None:
            policy, priority = self._previous_scheduler
            try:
                calls.set_scheduler(policy, priority)
            except OSError:
                pass
        if self._previous_affinity is not None:
            try:
                calls.set_affinity(self._previous_affinity)
            except OSError:
                pass
        if self._previous_slack is not None:
            try:
                calls.set_timer_slack_ns(self._previous_slack)
            except OSError:
                pass


@contextlib.contextmanager
def cpu_latency_request(limit_us: int, os_calls: OsScheduling | None = None
                        ) -> Iterator[tuple[int | None, str | None]]:
    """Hold the CPU latency request ``limit_us`` (us; -1: none) for the ``with`` block, as
    the runner does for a loop (benchmarks that compare with the loops measure under the same
    request). Yields ``(limit held or None, warning or None)``; a refusal is the warning."""
    calls = os_calls if os_calls is not None else OsScheduling()
    if limit_us < 0:
        yield None, None
        return
    try:
        fd = calls.request_cpu_latency(limit_us)
    except (OSError, AttributeError) as error:
        yield None, f"CPU latency limit {limit_us} us refused ({error}): idle states as they are"
        return
    try:
        yield limit_us, None
    finally:
        with contextlib.suppress(OSError):
            calls.release_cpu_latency(fd)


def place_process_threads(
    cpus: tuple[int, ...], os_calls: OsScheduling | None = None
) -> tuple[tuple[int, ...] | None, list[str]]:
    """Pin the calling thread to ``cpus`` before the program starts its other threads, which
    inherit it (call it from the main thread before the link opens; the loop thread then moves
    to its own CPUs in :class:`LoopThreadScheduling`). ``()`` changes nothing. Returns
    ``(CPUs now, warnings)``; a refusal is a warning, never an exception."""
    calls = os_calls if os_calls is not None else OsScheduling()
    warnings: list[str] = []
    if cpus:
        try:
            calls.set_affinity(set(cpus))
        except (OSError, ValueError, AttributeError) as error:
            warnings.append(f"CPU affinity {list(cpus)} for the other threads refused: {error}")
    try:
        now = calls.get_affinity()
    except OSError:
        now = None
    return (None if now is None else tuple(sorted(now))), warnings


#: Name prefixes of Zenoh's runtime threads (zenoh 1.x tokio runtimes: app, acc, net, rx, tx).
ZENOH_THREAD_PREFIXES = ("app-", "acc-", "net-", "rx-", "tx-")


def _set_threads(policy: int, priority: int, label: str, name_prefixes: tuple[str, ...],
                 calls: OsScheduling) -> tuple[int, list[str]]:
    """Give every thread of this process whose name starts with one of ``name_prefixes`` the
    scheduling ``policy`` at ``priority``; returns ``(threads changed, warnings)``."""
    task_dir = "/proc/self/task"
    if not os.path.isdir(task_dir):
        return 0, ["thread scheduling: no /proc/self/task on this platform"]
    changed, warnings = 0, []
    for tid in os.listdir(task_dir):
        try:
            with open(f"{task_dir}/{tid}/comm") as comm:
                name = comm.read().strip()
        except OSError:
            continue  # the thread ended meanwhile
        if not name.startswith(name_prefixes):
            continue
        try:
            calls.set_thread_scheduler(int(tid), policy, priority)
            changed += 1
        except OSError as error:
            warnings.append(f"{label} for thread {name} refused: {error}")
    return changed, warnings


def raise_threads(
    priority: int,
    name_prefixes: tuple[str, ...] = ZENOH_THREAD_PREFIXES,
    os_calls: OsScheduling | None = None,
) -> tuple[int, list[str]]:
    """Put every thread of this process whose name starts with one of ``name_prefixes`` in
    SCHED_FIFO at ``priority`` (1..99). Returns ``(threads changed, warnings)``; a refusal is
    a warning, never an exception (Linux only: elsewhere nothing changes).

    Why (seen with ``perf sched``): a normal Zenoh thread woken on the
    CPU where a SCHED_FIFO loop thread is about to run waits in that CPU's queue for the
    whole of the loop's tick (up to 0.25 ms) even while the other CPU is idle; the normal
    scheduler moves it only at its next balancing tick. At a FIFO priority *below* the
    loop's, it still never preempts the loop, but the real-time scheduler pushes it to the
    free CPU at once, which cuts the link's one-way p99 several times (bench/loop_bench.py)."""
    calls = os_calls if os_calls is not None else OsScheduling()
    if not 1 <= priority <= MAX_FIFO_PRIORITY:
        raise ValueError(f"priority must be 1..{MAX_FIFO_PRIORITY} (got {priority})")
    return _set_threads(os.SCHED_FIFO, priority, f"SCHED_FIFO {priority}", name_prefixes,
                        calls)


def batch_threads(
    name_prefixes: tuple[str, ...] = ZENOH_THREAD_PREFIXES,
    os_calls: OsScheduling | None = None,
) -> tuple[int, list[str]]:
    """Put every thread of this process whose name starts with one of ``name_prefixes`` in
    SCHED_BATCH (no privilege needed). Returns ``(threads changed, warnings)``; a refusal is a
    warning, never an exception (Linux only: elsewhere nothing changes).

    Why: a SCHED_BATCH thread keeps its fair share of the CPU but its wake-ups never preempt
    the thread running on the CPU it wakes on; it runs there when that thread sleeps, or at
    once on an idle CPU. Each Zenoh message wakes a sending and a receiving thread; on a
    small machine where both CPUs are busy most of the time, those wake-ups preempt the loops
    and the emulated drives mid-tick, and every preemption of another CPU is an
    inter-processor interrupt, which a virtual CPU pays as an exit to the hypervisor. With
    batch Zenoh threads ``haptic-session``'s loops overrun less at the cost of a slightly
    longer median link delay (docs/measurements/link.md has the interleaved runs)."""
    calls = os_calls if os_calls is not None else OsScheduling()
    if not hasattr(os, "SCHED_BATCH"):
        return 0, ["SCHED_BATCH is not available on this platform"]
    return _set_threads(os.SCHED_BATCH, 0, "SCHED_BATCH", name_prefixes, calls)
