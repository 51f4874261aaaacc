"""Scheduling of the loop thread: LoopThreadScheduling against a fake OS (the order of the
calls, refusals as warnings, restoring on exit), then against the real Linux calls, each in a
fresh thread so the test process's main thread keeps its scheduling. No timing is asserted."""

from __future__ import annotations

import contextlib
import os
import sys
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

import pytest

from haptic.common.runtime import realtime
from haptic.common.runtime.realtime import (
    TIGHT_TIMER_SLACK_NS,
    AppliedScheduling,
    LoopThreadScheduling,
    OsScheduling,
    RealtimeSettings,
)
from haptic.common.runtime.runner import RealTimeRunner
from tests.helpers.fake_clock import FakeClock

SCHED_OTHER = getattr(os, "SCHED_OTHER", 0)
SCHED_FIFO = getattr(os, "SCHED_FIFO", 1)
DEFAULT_SLACK_NS = 50_000
linux_only = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux calls")


class FakeOs(OsScheduling):
    """A thread's scheduling state, with every call logged. ``refuse`` maps a method name to
    the exception it raises (and then changes nothing). ``rt_zero_slack`` mimics Linux >= 6.9:
    a SCHED_FIFO thread's timer slack reads 0 and cannot be set."""

    def __init__(self, *, refuse: dict[str, BaseException] | None = None,
                 rt_zero_slack: bool = False) -> None:
        super().__init__()
        self.refuse = refuse or {}
        self.rt_zero_slack = rt_zero_slack
        self.slack_ns = DEFAULT_SLACK_NS
        self.policy = SCHED_OTHER
        self.priority = 0
        self.affinity = {0, 1, 2, 3}
        self.calls: list[tuple[str, Any]] = []

    def _call(self, name: str, argument: Any = None) -> None:
        self.calls.append((name, argument))
        if name in self.refuse:
            raise self.refuse[name]

    def setters(self) -> list[tuple[str, Any]]:
        return [call for call in self.calls if call[0].startswith("set_")]

    def get_timer_slack_ns(self) -> int | None:
        self._call("get_timer_slack_ns")
        return 0 if self.rt_zero_slack and self.policy == SCHED_FIFO else self.slack_ns

    def set_timer_slack_ns(self, slack_ns: int) -> None:
        self._call("set_timer_slack_ns", slack_ns)
        if not (self.rt_zero_slack and self.policy == SCHED_FIFO):
            self.slack_ns = slack_ns

    def get_scheduler(self) -> tuple[int, int]:
        self._call("get_scheduler")
        return self.policy, self.priority

    def set_scheduler(self, policy: int, priority: int) -> None:
        self._call("set_scheduler", (policy, priority))
        self.policy, self.priority = policy, priority

    def get_affinity(self) -> set[int] | None:
        self._call("get_affinity")
        return set(self.affinity)

    def set_affinity(self, cpus: set[int]) -> None:
        self._call("set_affinity", set(cpus))
        self.affinity = set(cpus)

    def request_cpu_latency(self, limit_us: int) -> int:
        self._call("request_cpu_latency", limit_us)
        self.latency_requests = [*getattr(self, "latency_requests", []), limit_us]
        return 42

    def release_cpu_latency(self, fd: int) -> None:
        self._call("release_cpu_latency", fd)
        self.latency_requests = self.latency_requests[:-1]


def state(fake: FakeOs) -> tuple[int, int, int, set[int]]:
    return fake.slack_ns, fake.policy, fake.priority, fake.affinity


def in_thread(function: Callable[[], Any]) -> Any:
    """Run ``function`` in a fresh thread; return its result or re-raise what it raised
    (pytest.skip included)."""
    outcome: dict[str, Any] = {}

    def target() -> None:
        try:
            outcome["result"] = function()
        except BaseException as error:  # noqa: BLE001 - handed to the test's thread
            outcome["error"] = error

    thread = threading.Thread(target=target, name="rt-test")
    thread.start()
    thread.join(timeout=30.0)
    assert not thread.is_alive()
    if "error" in outcome:
        raise outcome["error"]
    return outcome["result"]


# --- RealtimeSettings --------------------------------------------------------------------


def test_settings_defaults_are_normal_scheduling_with_tight_timers():
    settings = RealtimeSettings()
    assert settings.priority == 0 and settings.tight_timers and settings.cpus == ()


@pytest.mark.parametrize("priority", [0, 1, 50, 99])
def test_settings_accept_priorities_0_to_99(priority):
    assert RealtimeSettings(priority=priority).priority == priority


@pytest.mark.parametrize("priority", [-1, 100, 1000])
def test_settings_reject_priorities_outside_0_to_99(priority):
    with pytest.raises(ValueError, match="priority"):
        RealtimeSettings(priority=priority)


def test_settings_take_a_cpu_latency_limit_or_none():
    assert RealtimeSettings().cpu_latency_limit_us == -1  # no request unless asked
    assert RealtimeSettings(cpu_latency_limit_us=0).cpu_latency_limit_us == 0
    with pytest.raises(ValueError, match="cpu_latency_limit_us"):
        RealtimeSettings(cpu_latency_limit_us=-2)


def test_settings_reject_negative_cpus():
    assert RealtimeSettings(cpus=(0, 3)).cpus == (0, 3)
    with pytest.raises(ValueError, match="cpus"):
        RealtimeSettings(cpus=(0, -1))


# --- LoopThreadScheduling on a fake OS ---------------------------------------------------


def test_applies_everything_and_restores_in_reverse_order():
    fake = FakeOs()
    before = state(fake)
    settings = RealtimeSettings(priority=40, tight_timers=True, cpus=(1,))
    with LoopThreadScheduling(settings, fake) as applied:
        assert state(fake) == (TIGHT_TIMER_SLACK_NS, SCHED_FIFO, 40, {1})
        assert fake.setters() == [
            ("set_timer_slack_ns", TIGHT_TIMER_SLACK_NS),
            ("set_affinity", {1}),
            ("set_scheduler", (SCHED_FIFO, 40)),
        ]
        assert applied.policy == "SCHED_FIFO" and applied.priority == 40
        assert applied.timer_slack_ns == TIGHT_TIMER_SLACK_NS
        assert applied.cpus == (1,)
        assert applied.warnings == []
        fake.calls.clear()
    assert state(fake) == before
    assert fake.setters() == [  # the reverse of the order they were applied in
        ("set_scheduler", (SCHED_OTHER, 0)),
        ("set_affinity", {0, 1, 2, 3}),
        ("set_timer_slack_ns", DEFAULT_SLACK_NS),
    ]


def test_restores_a_previous_fifo_priority_and_custom_slack():
    fake = FakeOs()
    fake.policy, fake.priority, fake.slack_ns = SCHED_FIFO, 10, 2_000
    with LoopThreadScheduling(RealtimeSettings(priority=70), fake):
        assert (fake.policy, fake.priority, fake.slack_ns) == (SCHED_FIFO, 70, 1)
    assert (fake.policy, fake.priority, fake.slack_ns) == (SCHED_FIFO, 10, 2_000)


def test_restores_when_the_body_raises():
    fake = FakeOs()
    before = state(fake)
    with pytest.raises(RuntimeError, match="loop failed"), LoopThreadScheduling(
        RealtimeSettings(priority=5, cpus=(0, 2)), fake
    ):
        assert state(fake) != before
        raise RuntimeError("loop failed")
    assert state(fake) == before


def test_priority_0_and_no_tight_timers_change_nothing():
    fake = FakeOs()
    before = state(fake)
    with LoopThreadScheduling(RealtimeSettings(priority=0, tight_timers=False), fake) as applied:
        assert fake.setters() == []
        assert state(fake) == before
    assert fake.setters() == []
    # what the thread has is still read back and reported
    assert applied.policy == "SCHED_OTHER" and applied.priority == 0
    assert applied.timer_slack_ns == DEFAULT_SLACK_NS
    assert applied.cpus == (0, 1, 2, 3)
    assert applied.warnings == []


@pytest.mark.parametrize(
    ("method", "error", "warning"),
    [
        ("set_timer_slack_ns", OSError(1, "Operation not permitted"), "tight timers refused"),
        ("set_affinity", OSError(22, "Invalid argument"), "CPU affinity [2] refused"),
        ("set_scheduler", PermissionError(1, "Operation not permitted"),
         "SCHED_FIFO 40 refused"),
    ],
)
def test_one_refusal_is_a_warning_and_the_rest_applies(method, error, warning):
    fake = FakeOs(refuse={method: error})
    before = state(fake)
    settings = RealtimeSettings(priority=40, tight_timers=True, cpus=(2,))
    with LoopThreadScheduling(settings, fake) as applied:
        assert len(applied.warnings) == 1
        assert applied.warnings[0].startswith(warning)
        assert str(error.strerror) in applied.warnings[0]
        refused = {
            "set_timer_slack_ns": (before[0], fake.slack_ns),
            "set_affinity": (before[3], fake.affinity),
            "set_scheduler": (before[1:3], (fake.policy, fake.priority)),
        }
        unchanged, now = refused[method]
        assert now == unchanged
        applied_ok = {
            "set_timer_slack_ns": fake.slack_ns == TIGHT_TIMER_SLACK_NS,
            "set_affinity": fake.affinity == {2},
            "set_scheduler": (fake.policy, fake.priority) == (SCHED_FIFO, 40),
        }
        assert all(ok for name, ok in applied_ok.items() if name != method)
        fake.calls.clear()
    assert state(fake) == before
    # the refused setting is not "restored" on exit: nothing of it was applied
    assert method not in [name for name, _ in fake.setters()]
    assert len(fake.setters()) == 2


def test_every_refusal_leaves_the_thread_as_it_was():
    denied = PermissionError(1, "Operation not permitted")
    fake = FakeOs(refuse={
        "set_timer_slack_ns": denied, "set_affinity": denied, "set_scheduler": denied,
    })
    before = state(fake)
    settings = RealtimeSettings(priority=99, tight_timers=True, cpus=(0, 1))
    with LoopThreadScheduling(settings, fake) as applied:
        assert state(fake) == before
        assert len(applied.warnings) == 3
        assert "normal scheduling" in applied.warnings[2]
        assert applied.policy == "SCHED_OTHER" and applied.priority == 0
        assert applied.timer_slack_ns == DEFAULT_SLACK_NS
        fake.calls.clear()
    assert fake.setters() == []  # nothing to restore
    assert state(fake) == before


def test_a_refused_read_of_the_previous_value_skips_the_setting():
    fake = FakeOs(refuse={"get_scheduler": OSError(3, "No such process")})
    with LoopThreadScheduling(RealtimeSettings(priority=40, tight_timers=False), fake) as applied:
        # without the previous policy it could not be restored, so it is not changed
        assert ("set_scheduler", (SCHED_FIFO, 40)) not in fake.setters()
        assert (fake.policy, fake.priority) == (SCHED_OTHER, 0)
        assert applied.warnings and "SCHED_FIFO 40 refused" in applied.warnings[0]
    assert fake.setters() == []


def test_applied_is_what_the_os_reports_not_what_was_asked():
    # Linux >= 6.9 gives SCHED_FIFO threads zero timer slack whatever was set
    fake = FakeOs(rt_zero_slack=True)
    with LoopThreadScheduling(RealtimeSettings(priority=20), fake) as applied:
        assert applied.policy == "SCHED_FIFO"
        assert applied.timer_slack_ns == 0
        assert applied.describe() == "SCHED_FIFO 20, timer slack 0 ns, CPUs 0,1,2,3"
    assert state(fake) == (DEFAULT_SLACK_NS, SCHED_OTHER, 0, {0, 1, 2, 3})


def test_the_cpu_latency_request_is_held_for_the_run_and_released():
    fake = FakeOs()
    with LoopThreadScheduling(RealtimeSettings(cpu_latency_limit_us=0), fake) as applied:
        assert fake.latency_requests == [0]
        assert applied.cpu_latency_limit_us == 0 and applied.warnings == []
        assert applied.describe().endswith("CPU latency limit 0 us")
    assert fake.latency_requests == []
    assert ("release_cpu_latency", 42) in fake.calls  # the descriptor it was given
    fake = FakeOs()
    with LoopThreadScheduling(RealtimeSettings(), fake) as applied:  # -1: no request
        assert applied.cpu_latency_limit_us is None
    assert [name for name, _ in fake.calls if "latency" in name] == []


def test_a_refused_cpu_latency_request_is_a_warning_and_nothing_is_released():
    fake = FakeOs(refuse={"request_cpu_latency": PermissionError(13, "Permission denied")})
    settings = RealtimeSettings(priority=40, cpu_latency_limit_us=0)
    with LoopThreadScheduling(settings, fake) as applied:
        assert applied.cpu_latency_limit_us is None
        assert applied.warnings == [
            "CPU latency limit 0 us refused ([Errno 13] Permission denied): idle states as "
            "they are"]
        assert applied.policy == "SCHED_FIFO"  # the rest applies
    assert "release_cpu_latency" not in [name for name, _ in fake.calls]


def test_cpu_latency_request_holds_for_the_block_or_says_why_not():
    fake = FakeOs()
    with realtime.cpu_latency_request(0, fake) as (held, warning):
        assert (held, warning, fake.latency_requests) == (0, None, [0])
    assert fake.latency_requests == []
    with realtime.cpu_latency_request(-1, fake) as (held, warning):
        assert (held, warning) == (None, None)
    assert [name for name, _ in fake.calls].count("request_cpu_latency") == 1
    refusing = FakeOs(refuse={"request_cpu_latency": PermissionError(13, "Permission denied")})
    with realtime.cpu_latency_request(5, refusing) as (held, warning):
        assert held is None and warning.startswith("CPU latency limit 5 us refused")
    assert "release_cpu_latency" not in [name for name, _ in refusing.calls]


def test_describe_and_summary():
    applied = AppliedScheduling(
        policy="SCHED_FIFO", priority=40, timer_slack_ns=1, cpus=(0, 1),
        warnings=["CPU affinity [7] refused: bad"], gil_switch_interval_s=0.0002,
    )
    assert applied.describe() == "SCHED_FIFO 40, timer slack 1 ns, CPUs 0,1"
    summary = applied.as_summary()
    assert summary == {
        "scheduling": "SCHED_FIFO 40, timer slack 1 ns, CPUs 0,1",
        "scheduling_policy": "SCHED_FIFO",
        "scheduling_priority": 40,
        "timer_slack_ns": 1,
        "gil_switch_interval_s": 0.0002,
        "cpu_latency_limit_us": None,
        "scheduling_warnings": ["CPU affinity [7] refused: bad"],
    }
    summary["scheduling_warnings"].append("x")  # a copy: the summary never aliases the state
    assert applied.warnings == ["CPU affinity [7] refused: bad"]
    # normal scheduling shows no priority; unknown slack and CPUs are left out
    assert AppliedScheduling().describe() == "SCHED_OTHER"
    assert AppliedScheduling(timer_slack_ns=50_000).describe() == (
        "SCHED_OTHER, timer slack 50000 ns"
    )


# --- the real Linux calls, each in a fresh thread ----------------------------------------


def _fifo_permitted() -> bool:
    def attempt() -> bool:
        try:
            os.sched_setscheduler(0, SCHED_FIFO, os.sched_param(1))
        except (OSError, AttributeError):
            return False
        os.sched_setscheduler(0, SCHED_OTHER, os.sched_param(0))
        return True

    return bool(in_thread(attempt))


@linux_only
def test_tight_timers_on_the_calling_thread_only_and_restored():
    main_before = OsScheduling().get_timer_slack_ns()

    def body() -> tuple[int | None, ...]:
        calls = OsScheduling()
        before = calls.get_timer_slack_ns()
        with LoopThreadScheduling(RealtimeSettings(priority=0, tight_timers=True)) as applied:
            inside = calls.get_timer_slack_ns()
        return before, inside, applied.timer_slack_ns, calls.get_timer_slack_ns()

    before, inside, reported, after = in_thread(body)
    assert before is not None and before > TIGHT_TIMER_SLACK_NS
    assert inside == reported == TIGHT_TIMER_SLACK_NS
    assert after == before
    assert OsScheduling().get_timer_slack_ns() == main_before  # the main thread untouched


@linux_only
def test_real_fifo_inside_and_normal_after():
    if not _fifo_permitted():
        pytest.skip("SCHED_FIFO is not permitted here (needs CAP_SYS_NICE or an rtprio limit)")

    def body() -> tuple[Any, ...]:
        with LoopThreadScheduling(RealtimeSettings(priority=3, tight_timers=True)) as applied:
            inside = (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority)
        after = (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority)
        return applied, inside, after, OsScheduling().get_timer_slack_ns()

    applied, inside, after, slack_after = in_thread(body)
    assert inside == (SCHED_FIFO, 3)
    assert applied.policy == "SCHED_FIFO" and applied.priority == 3
    assert applied.warnings == []
    assert after == (SCHED_OTHER, 0)
    assert slack_after is not None and slack_after > TIGHT_TIMER_SLACK_NS
    assert os.sched_getscheduler(0) == SCHED_OTHER  # the main thread untouched


@linux_only
def test_real_affinity_inside_and_restored():
    allowed = sorted(os.sched_getaffinity(0))

    def body() -> tuple[Any, ...]:
        with LoopThreadScheduling(RealtimeSettings(tight_timers=False, cpus=(allowed[0],))) as a:
            inside = os.sched_getaffinity(0)
        return a, inside, os.sched_getaffinity(0)

    applied, inside, after = in_thread(body)
    assert inside == {allowed[0]} and applied.cpus == (allowed[0],)
    assert sorted(after) == allowed
    assert sorted(os.sched_getaffinity(0)) == allowed


@linux_only
def test_real_cpu_latency_request_holds_during_the_run_only():
    device = realtime.CPU_LATENCY_DEVICE
    if not os.access(device, os.R_OK | os.W_OK):
        pytest.skip(f"{device} is not readable and writable here (needs root or a udev rule)")

    def current_us() -> int:  # the system's effective limit, us (no request: 2e9)
        with open(device, "rb") as qos:
            return int.from_bytes(qos.read(4), sys.byteorder, signed=True)

    before = current_us()
    with LoopThreadScheduling(RealtimeSettings(tight_timers=False,
                                               cpu_latency_limit_us=0)) as applied:
        inside = current_us()
    assert applied.cpu_latency_limit_us == 0 and applied.warnings == []
    assert inside == 0
    assert current_us() == before


# --- the runner reports its scheduling ---------------------------------------------------


def run_fake(settings: RealtimeSettings | None) -> Any:
    clock = FakeClock()
    runner = RealTimeRunner(
        0.00054, lambda tick, now: None, duration_s=0.01, clock_ns=clock.clock,
        sleep=clock.sleep, handle_signals=False, show_status=False, realtime=settings,
    )
    return runner.run()


SCHEDULING_KEYS = {
    "scheduling", "scheduling_policy", "scheduling_priority", "timer_slack_ns",
    "scheduling_warnings",
}


def test_runner_without_realtime_reports_no_scheduling():
    stats = run_fake(None)
    assert stats.scheduling is None
    assert not SCHEDULING_KEYS & set(stats.as_summary())


@linux_only
def test_runner_reports_tight_timers_in_its_summary():
    stats = in_thread(lambda: run_fake(RealtimeSettings(priority=0, tight_timers=True)))
    assert stats.steps > 0 and stats.stop_reason == "duration"
    assert stats.scheduling is not None
    summary = stats.as_summary()
    assert SCHEDULING_KEYS <= set(summary)
    assert summary["scheduling_policy"] == "SCHED_OTHER"
    assert summary["timer_slack_ns"] == TIGHT_TIMER_SLACK_NS
    assert summary["scheduling_warnings"] == []
    assert summary["scheduling"] == stats.scheduling.describe()
    assert "timer slack 1 ns" in summary["scheduling"]


def test_runner_runs_on_when_fifo_is_refused(monkeypatch):
    def refuse(self: OsScheduling, policy: int, priority: int) -> None:
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(realtime.OsScheduling, "set_scheduler", refuse)
    stats = in_thread(lambda: run_fake(RealtimeSettings(priority=40, tight_timers=False)))
    assert stats.steps > 0 and stats.stop_reason == "duration"
    summary = stats.as_summary()
    assert summary["scheduling_policy"] == "SCHED_OTHER"
    assert len(summary["scheduling_warnings"]) == 1
    assert summary["scheduling_warnings"][0].startswith("SCHED_FIFO 40 refused")


@linux_only
def test_runner_under_fifo_reports_it_and_gives_it_back():
    if not _fifo_permitted():
        pytest.skip("SCHED_FIFO is not permitted here (needs CAP_SYS_NICE or an rtprio limit)")

    def body() -> tuple[Any, int]:
        stats = run_fake(RealtimeSettings(priority=2, tight_timers=True))
        return stats, os.sched_getscheduler(0)

    stats, policy_after = in_thread(body)
    summary = stats.as_summary()
    assert summary["scheduling_policy"] == "SCHED_FIFO"
    assert summary["scheduling_priority"] == 2
    assert summary["scheduling"].startswith("SCHED_FIFO 2")
    assert summary["scheduling_warnings"] == []
    assert policy_after == SCHED_OTHER


class ThreadRecorder(OsScheduling):
    """Records set_thread_scheduler calls; refuses for the thread ids in ``refuse``."""

    def __init__(self, refuse: set[int] | None = None) -> None:
        super().__init__()
        self.refuse = refuse or set()
        self.calls: list[tuple[int, int, int]] = []

    def set_thread_scheduler(self, thread_id: int, policy: int, priority: int) -> None:
        if thread_id in self.refuse:
            raise PermissionError(1, "Operation not permitted")
        self.calls.append((thread_id, policy, priority))


@contextlib.contextmanager
def _named_threads(*names: str) -> Iterator[dict[str, int]]:
    """Threads with these OS names (what Zenoh's threads are recognised by), alive inside:
    name -> native thread id."""
    stop = threading.Event()
    ids: dict[str, int] = {}

    def body(name: str) -> None:
        with open("/proc/thread-self/comm", "w") as comm:
            comm.write(name)
        ids[name] = threading.get_native_id()
        stop.wait(5.0)

    threads = [threading.Thread(target=body, args=(name,), daemon=True) for name in names]
    for thread in threads:
        thread.start()
    try:
        deadline = time.monotonic() + 5.0
        while len(ids) < len(names) and time.monotonic() < deadline:
            time.sleep(0.01)
        yield ids
    finally:
        stop.set()
        for thread in threads:
            thread.join()


@pytest.mark.skipif(not os.path.isdir("/proc/self/task"), reason="needs Linux /proc")
def test_raise_threads_selects_threads_by_name_and_reports_refusals():
    from haptic.common.runtime.realtime import raise_threads

    # names no Zenoh thread of this test process has (earlier tests leave Zenoh's runtimes)
    with _named_threads("qrx-test", "qtx-test", "other") as ids:
        rx_id, tx_id, other_id = ids["qrx-test"], ids["qtx-test"], ids["other"]
        recorder = ThreadRecorder(refuse={tx_id})
        changed, warnings = raise_threads(7, ("qrx-", "qtx-"), recorder)
        assert changed == 1
        assert [c[0] for c in recorder.calls] == [rx_id]
        assert recorder.calls[0][1:] == (os.SCHED_FIFO, 7)
        assert len(warnings) == 1 and "qtx-test" in warnings[0]
        assert other_id not in [c[0] for c in recorder.calls]


@pytest.mark.skipif(not os.path.isdir("/proc/self/task") or not hasattr(os, "SCHED_BATCH"),
                    reason="needs Linux /proc and SCHED_BATCH")
def test_batch_threads_puts_the_named_threads_in_sched_batch_and_no_other():
    from haptic.common.runtime.realtime import batch_threads

    with _named_threads("qbrx-test", "qbtx-test", "other") as ids:
        recorder = ThreadRecorder(refuse={ids["qbtx-test"]})
        changed, warnings = batch_threads(("qbrx-", "qbtx-"), recorder)
        assert changed == 1 and recorder.calls == [(ids["qbrx-test"], os.SCHED_BATCH, 0)]
        assert len(warnings) == 1 and "qbtx-test" in warnings[0]
        # for real (no privilege needed): the named threads change, the others do not
        changed, warnings = batch_threads(("qbrx-", "qbtx-"))
        assert (changed, warnings) == (2, [])
        assert os.sched_getscheduler(ids["qbrx-test"]) == os.SCHED_BATCH
        assert os.sched_getscheduler(ids["qbtx-test"]) == os.SCHED_BATCH
        assert os.sched_getscheduler(ids["other"]) == os.SCHED_OTHER


def test_raise_threads_rejects_a_priority_out_of_range():
    from haptic.common.runtime.realtime import raise_threads

    with pytest.raises(ValueError):
        raise_threads(0, ("rx-",), ThreadRecorder())


# --- the GIL switch interval and the other threads' CPUs ----------------------------------


def test_gil_switch_interval_is_set_for_the_loop_and_restored():
    before = sys.getswitchinterval()
    with LoopThreadScheduling(RealtimeSettings(tight_timers=False, gil_switch_interval_s=0.0002),
                              FakeOs()) as applied:
        inside = sys.getswitchinterval()
    assert inside == pytest.approx(0.0002)
    assert applied.gil_switch_interval_s == pytest.approx(0.0002)
    assert applied.as_summary()["gil_switch_interval_s"] == pytest.approx(0.0002)
    assert sys.getswitchinterval() == before


def test_gil_switch_interval_0_leaves_pythons_own():
    before = sys.getswitchinterval()
    with LoopThreadScheduling(RealtimeSettings(tight_timers=False), FakeOs()) as applied:
        assert sys.getswitchinterval() == before
    assert applied.gil_switch_interval_s == before
    with pytest.raises(ValueError, match="gil_switch_interval_s"):
        RealtimeSettings(gil_switch_interval_s=-1.0)


def test_place_process_threads_on_a_fake_os():
    fake = FakeOs()
    cpus, warnings = realtime.place_process_threads((1, 2), fake)
    assert cpus == (1, 2) and warnings == [] and fake.affinity == {1, 2}
    assert realtime.place_process_threads((), fake) == ((1, 2), [])
    refusing = FakeOs(refuse={"set_affinity": OSError(22, "Invalid argument")})
    cpus, warnings = realtime.place_process_threads((7,), refusing)
    assert cpus == (0, 1, 2, 3)  # unchanged
    assert len(warnings) == 1 and "CPU affinity [7] for the other threads refused" in warnings[0]
