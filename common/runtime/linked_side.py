"""What both networked programs' tick sides hold (master/program_stages.py,
slave_sim/program_stages.py, run by common/runtime/tick_driver.py): the link to the peer, the
side's one-lane tick and its supervisor, the program's harness, the run's records (trace,
recording), the inert monitor, the ROS 2 publisher and the clock, and the summary's peak
force. Each side adds its own stages and figures.

Only construction and off-the-loop reads live here: a tick's stages stay the side's own
methods, so the hot path makes no extra call.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from haptic.common.records.run_recording import RunRecording
from haptic.common.records.trace import TraceRecorder
from haptic.common.runtime.inert import InertMonitor
from haptic.common.runtime.program_harness import ProgramHarness
from haptic.common.wire.link import Link


class LinkedSide:
    """The parts of a networked program's side both programs share (see the module).

    ``tick``: the side's tick, configured for one lane by the subclass; its first supervisor
    is :attr:`supervisor`; ``trace``: the trace kept every N ticks; ``recording``: the run's
    MCAP recording or None; ``inert``: the inert monitor; ``ros2``: the ROS 2 publisher or
    None; ``clock_ns``: the clock the whole-tick call reads its boundary with (ns).
    """

    def __init__(self, link: Link, tick: Any, harness: ProgramHarness, trace: TraceRecorder,
                 recording: RunRecording | None, inert: InertMonitor, ros2: Any | None,
                 clock_ns: Callable[[], int]) -> None:
        self.link = link
        self.tick = tick
        self.supervisor = tick.supervisors[0]
        self.harness = harness
        self.trace = trace
        self.recording = recording
        self.inert = inert
        self.ros2 = ros2
        self.clock_ns = clock_ns
        #: the largest force magnitude this side reported, N (the summary's)
        self.max_force_N = 0.0
        #: the watchdog's message age limit, s (the inert monitor's "peer alive" test)
        self._max_age_s = link.config.max_message_age_s

    def link_status(self) -> dict[str, Any]:
        """The link's figures and the watchdog's state and trips (the ROS 2 status's common
        part; read off the loop)."""
        watchdog = self.supervisor.watchdog
        return {**self.link.summary(), "watchdog_state": watchdog.state.value,
                "watchdog_trips": watchdog.trips}


__all__ = ["LinkedSide"]
