"""The inert-session monitor at exact values (common/runtime/inert.py): the threshold itself,
a timer that starts again after each interruption, the events' times and words, episodes and
their time summed, and the summary of a session that never was or still is inert.
tests/common/runtime/test_inert.py runs it in the programs."""

from __future__ import annotations

from haptic.common.runtime.inert import InertMonitor


def test_a_fresh_monitor_is_not_inert() -> None:
    monitor = InertMonitor(0.5)
    assert (monitor.inert, monitor.episodes, monitor.inert_time_s, monitor.reason) == (
        False, 0, 0.0, "")
    assert monitor.events == [] and monitor.status() == ""
    assert monitor.summary(10.0) == {"inert": False, "inert_episodes": 0, "inert_time_s": 0.0,
                                     "inert_reason": None, "inert_after_s": 0.5}
    assert InertMonitor(0.5).events is not monitor.events  # each its own list


def test_inert_at_exactly_the_threshold_with_the_reason_it_started_with() -> None:
    monitor = InertMonitor(1.5)
    assert not monitor.update(1.0, True, False, "gate")
    assert not monitor.update(2.25, True, False, "gate")
    assert monitor.update(2.5, True, False, "gate")  # 1.5 s after the first tick off
    assert monitor.update(3.0, True, False, "resync")  # still the same episode
    assert monitor.reason == "gate" and monitor.status() == "  INERT: gate"
    assert monitor.events == [{"time_s": 2.5, "kind": "inert",
                               "reason": "forces off 1.5 s with the peer present: gate"}]


def test_each_interruption_starts_the_wait_again() -> None:
    monitor = InertMonitor(1.0)
    monitor.update(0.0, True, False, "gate")
    monitor.update(0.75, True, True, "gate")  # forces on for a moment
    assert not monitor.update(1.5, True, False, "gate")  # 1.5 s after the first, 0 after
    assert not monitor.update(2.25, True, False, "gate")
    monitor.update(2.5, False, False, "gate")  # the peer went
    assert not monitor.update(3.0, True, False, "gate")
    assert monitor.update(4.0, True, False, "gate")
    assert monitor.episodes == 1 and [e["time_s"] for e in monitor.events] == [4.0]


def test_episodes_are_counted_and_their_time_summed_up_to_the_end() -> None:
    monitor = InertMonitor(1.0)
    monitor.update(0.0, True, False, "gate")
    monitor.update(1.0, True, False, "gate")  # inert from 1.0
    assert not monitor.update(3.5, True, True, "gate")  # cleared: 2.5 s
    monitor.update(4.0, True, False, "work-area stop")
    monitor.update(5.0, True, False, "work-area stop")  # inert from 5.0
    assert not monitor.update(5.25, False, False, "work-area stop")  # 0.25 s more
    monitor.update(6.0, True, False, "resync")
    monitor.update(7.0, True, False, "resync")  # inert from 7.0, to the end
    assert [(e["time_s"], e["kind"]) for e in monitor.events] == [
        (1.0, "inert"), (3.5, "inert_cleared"), (5.0, "inert"), (5.25, "inert_cleared"),
        (7.0, "inert")]
    assert [e["reason"] for e in monitor.events if e["kind"] == "inert_cleared"] == [
        "forces on", "peer gone"]
    assert monitor.inert_time_s == 2.75
    assert monitor.summary(9.0) == {"inert": True, "inert_episodes": 3, "inert_time_s": 4.75,
                                    "inert_reason": "resync", "inert_after_s": 1.0}
    monitor.update(9.0, True, True, "resync")
    assert monitor.summary(20.0)["inert_time_s"] == 4.75  # over: nothing more counted
