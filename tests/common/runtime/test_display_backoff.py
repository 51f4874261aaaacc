"""The display gives way to the loops: the back-off's scale, the programs' display thread
following its loop's counts, and the view following both sides' statuses."""

from __future__ import annotations

import json
import threading
import time
from typing import Any

import numpy as np
import pytest

from haptic.common.runtime.display import DisplayPublisher
from haptic.common.runtime.display_backoff import DisplayBackoff
from haptic.view.server import ViewServer
from haptic.view.state import ViewState


def test_scale_halves_per_update_with_overruns_down_to_the_floor() -> None:
    backoff = DisplayBackoff()
    assert backoff.update(0.0, 0, 0) == 1.0  # the baseline
    assert backoff.update(0.2, 370, 0) == 1.0  # on time: no change
    scales = [backoff.update(0.2 * i, 370 * i, 10 * (i - 2)) for i in range(3, 10)]
    assert scales == [0.5, 0.25, 0.125, 0.0625, 0.0625, 0.0625, 0.0625]
    assert backoff.backoffs == 4


def test_one_overrun_in_a_thousand_ticks_is_within_the_limit() -> None:
    backoff = DisplayBackoff()
    backoff.update(0.0, 0, 0)
    assert backoff.update(1.0, 1000, 1) == 1.0
    assert backoff.update(2.0, 2000, 3) == 0.5  # 2 in 1000: beyond 0.1 %


def test_scale_recovers_step_by_step_after_quiet_periods() -> None:
    backoff = DisplayBackoff(recover_s=2.0)
    backoff.update(0.0, 0, 0)
    backoff.update(0.2, 370, 50)
    backoff.update(0.4, 740, 100)
    assert backoff.scale == 0.25
    assert backoff.update(1.0, 1850, 100) == 0.25  # quiet, but not 2 s yet
    assert backoff.update(2.5, 4600, 100) == 0.5
    assert backoff.update(3.0, 5500, 100) == 0.5
    assert backoff.update(4.6, 8500, 100) == 1.0
    assert backoff.update(9.0, 16000, 100) == 1.0


def test_counts_going_backwards_start_a_new_baseline_and_no_ticks_change_nothing() -> None:
    backoff = DisplayBackoff()
    backoff.update(0.0, 5000, 400)
    assert backoff.update(0.2, 100, 0) == 1.0  # a restarted program: no jump to judge
    assert backoff.update(0.4, 100, 50) == 1.0  # no new ticks: nothing to judge
    assert backoff.update(0.6, 470, 60) == 0.5


def test_invalid_settings_are_refused() -> None:
    with pytest.raises(ValueError):
        DisplayBackoff(min_scale=0.0)
    with pytest.raises(ValueError):
        DisplayBackoff(recover_s=0.0)


class _Session:
    """Collects what the publisher puts (the Zenoh session's ``put``)."""

    def __init__(self) -> None:
        self.puts: list[tuple[str, bytes]] = []
        self.lock = threading.Lock()

    def put(self, key: str, payload: bytes) -> None:
        with self.lock:
            self.puts.append((key, payload))

    def statuses(self) -> list[dict[str, Any]]:
        with self.lock:
            return [json.loads(payload) for key, payload in self.puts if "/status/" in key]


def _wait_for(condition: Any, timeout_s: float = 20.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if condition():
            return
        time.sleep(0.05)
    raise AssertionError("condition not met in time")


def test_display_thread_backs_off_while_its_loop_overruns_and_says_so() -> None:
    session = _Session()
    ticks = {"steps": 0, "overruns": 0}
    lock = threading.Lock()

    def loop_counts() -> tuple[int, int]:  # a loop overrunning every tenth tick
        with lock:
            ticks["steps"] += 400
            ticks["overruns"] += 40
            return ticks["steps"], ticks["overruns"]

    publisher = DisplayPublisher(session, "t", "slave", status_rate_hz=20.0)
    publisher.follow_loop(loop_counts, DisplayBackoff())
    publisher.offer_status({"link_received": 1}, [])
    with publisher:
        _wait_for(lambda: publisher.scale == 0.0625)
        _wait_for(lambda: any(s.get("display_scale") == 0.0625 for s in session.statuses()))
    status = session.statuses()[-1]
    assert status["loop_steps"] > 0 and status["loop_overruns"] == status["loop_steps"] // 10
    figures = publisher.figures
    assert figures["display_backoffs"] == 4 and figures["display_lowest_scale"] == 0.0625


def test_display_thread_without_backoff_keeps_its_rates_and_publishes_the_counts() -> None:
    session = _Session()
    publisher = DisplayPublisher(session, "t", "master", status_rate_hz=20.0)
    publisher.follow_loop(lambda: (1000, 900), None)
    publisher.offer_status({}, [])
    with publisher:
        _wait_for(lambda: len(session.statuses()) >= 3)
    assert publisher.scale == 1.0 and publisher.figures["display_backoffs"] == 0
    assert session.statuses()[-1]["loop_overruns"] == 900


class _Clock:
    def __init__(self) -> None:
        self.now_s = 0.0

    def __call__(self) -> float:
        return self.now_s


def _status(side: str, steps: Any, overruns: Any) -> dict[str, Any]:
    return {"side": side, "loop_steps": steps, "loop_overruns": overruns, "link": {}}


def test_view_follows_the_worse_side_and_recovers() -> None:
    clock = _Clock()
    state = ViewState(clock=clock)
    state.update(status=_status("master", 0, 0))
    state.update(status=_status("slave", 0, 0))
    for i in range(1, 5):
        clock.now_s = 0.2 * i
        state.update(status=_status("master", 370 * i, 0))
        state.update(status=_status("slave", 370 * i, 30 * i))  # the slave overruns
    assert state.scale == 0.0625 and state.snapshot()["view_scale"] == 0.0625
    for i in range(5, 50):
        clock.now_s = 0.2 * i
        state.update(status=_status("master", 370 * i, 0))
        state.update(status=_status("slave", 370 * i, 120))
    assert state.scale == 1.0 and state.lowest_scale == 0.0625


def test_view_ignores_loop_counts_that_are_not_counts() -> None:
    clock = _Clock()
    state = ViewState(clock=clock)
    for bad in ((-1, 0), (1.5, 0), ("9", 0), (True, 0), (None, 0), (10, 1e300)):
        state.update(status=_status("slave", *bad))
    state.update(status=_status("master", 0, 0))
    state.update(status=_status("slave", 0, 0))
    state.update(status=_status("stranger", 0, 0))  # a third side is nobody's
    clock.now_s = 0.2
    state.update(status=_status("stranger", 100, 100))
    assert state.bad_loop_counts == 8 and state.scale == 1.0


def test_view_without_backoff_keeps_its_rate() -> None:
    clock = _Clock()
    state = ViewState(backoff=False, clock=clock)
    for i in range(5):
        clock.now_s = 0.2 * i
        state.update(status=_status("slave", 370 * i, 100 * i))
    assert state.scale == 1.0


def test_server_reports_the_frame_scale() -> None:
    clock = _Clock()
    state = ViewState(clock=clock)
    state.update(status=_status("slave", 0, 0))
    clock.now_s = 0.2
    state.update(status=_status("slave", 370, 37))
    with ViewServer(state, port=0) as server:
        stats = server.stats()
    assert stats["frame_scale"] == 0.5 and stats["lowest_frame_scale"] == 0.5


class _Publisher:
    """A declared publisher of :class:`_WatchedSession`: puts go to the session; its
    ``matching_status.matching`` is the session's ``watched``."""

    def __init__(self, session: _WatchedSession, key: str) -> None:
        self._session, self._key = session, key

    @property
    def matching_status(self) -> Any:
        class Status:
            matching = self._session.watched
        return Status()

    def put(self, payload: bytes) -> None:
        self._session.put(self._key, payload)

    def undeclare(self) -> None:
        self._session.undeclared += 1


class _WatchedSession(_Session):
    """A session whose publishers match a subscriber only while ``watched``."""

    def __init__(self) -> None:
        super().__init__()
        self.watched = False
        self.undeclared = 0

    def declare_publisher(self, key: str) -> _Publisher:
        return _Publisher(self, key)

    def keys(self) -> list[str]:
        with self.lock:
            return [key for key, _ in self.puts]


def test_nothing_is_encoded_for_keys_nobody_watches_and_a_new_viewer_gets_the_layout() -> None:
    session = _WatchedSession()
    clay_maps: list[Any] = []
    heights = np.zeros((8, 16))
    publisher = DisplayPublisher(
        session, "t", "slave", status_rate_hz=20.0, clay_rate_hz=20.0,
        clay_source=lambda: heights, layout={"cells_x": 16, "cells_y": 8}, factors=(1, 1),
        on_clay=lambda time_ns, reduced: clay_maps.append(reduced))
    publisher.follow_loop(lambda: (100, 0), DisplayBackoff())
    publisher.offer_status({}, [])
    publisher.offer_state({"tool_force_N": [1.0, 0.0]})
    with publisher:
        _wait_for(lambda: publisher.unwatched_skips >= 6 and len(clay_maps) >= 3)
        assert session.keys() == []  # nobody watches: nothing published
        assert publisher.publications == 0
        assert not publisher.status_watched  # the loop need not offer its status
        assert not publisher.state_watched  # nor its state
        session.watched = True
        _wait_for(lambda: {"t/workpiece", "t/status/slave", "t/clay"} <= set(session.keys()))
        assert publisher.status_watched
        publisher.offer_state({"tool_force_N": [2.0, 0.0]})
        _wait_for(lambda: "t/view/slave" in session.keys())
        assert publisher.state_watched
    keys = session.keys()
    assert keys.count("t/workpiece") >= 1 and session.undeclared == 4
    assert publisher.figures["display_unwatched_skips"] >= 6



class _CountingSession(_WatchedSession):
    """A :class:`_WatchedSession` that counts how often its publishers' matching status is
    read (once per key per wake-up of the display thread that looks at it)."""

    def __init__(self) -> None:
        super().__init__()
        self.matching_reads = 0

    def declare_publisher(self, key: str) -> _Publisher:
        session = self

        class Counting(_Publisher):
            @property
            def matching_status(self) -> Any:
                with session.lock:
                    session.matching_reads += 1
                return super().matching_status

        return Counting(self, key)


def test_the_display_thread_wakes_only_when_something_is_due() -> None:
    """Every wake-up of the display thread takes the program's GIL at a time the loop does
    not choose (module docstring of common/runtime/display.py): with nobody watching it looks
    at each key every UNWATCHED_CHECK_S or at the status rate, not every 5 ms; watched, at
    the publications' own rates. Counts over wall time only bound the wake-ups from above,
    which a slow machine can only lower."""
    session = _CountingSession()
    heights = np.zeros((8, 16))
    publisher = DisplayPublisher(
        session, "t", "slave", clay_source=lambda: heights,
        layout={"cells_x": 16, "cells_y": 8}, factors=(1, 1))
    publisher.follow_loop(lambda: (100, 0), DisplayBackoff())
    publisher.offer_status({}, [])
    publisher.offer_state({"tool_force_N": [1.0, 0.0]})
    with publisher:
        time.sleep(1.0)
        unwatched_reads = session.matching_reads
        # 5 status looks a second (the back-off reads the loop's counts), each looking at
        # the layout too, and 4 a second at the state and the clay: about 18 in 1 s
        # (the old 5 ms wait: about 800)
        assert 4 <= unwatched_reads <= 40
        assert session.keys() == []
        session.watched = True
        _wait_for(lambda: {"t/workpiece", "t/status/slave", "t/clay"} <= set(session.keys()))
        before = session.matching_reads
        time.sleep(1.0)
        watched_reads = session.matching_reads - before
    # watched: the state at 60 Hz, the clay at 10 Hz, the status at 5 Hz, and the layout
    # looked at on each of those wake-ups: at most about 150 reads in 1 s
    assert watched_reads <= 200
    assert publisher.publications > 0
