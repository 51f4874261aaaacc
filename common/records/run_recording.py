"""What a program records of its run (``--record FILE``), on top of :class:`McapRecorder`.

Channels (JSON schema, JSON messages; ``<side>`` is ``master`` or ``slave``):

- ``/<side>/state``: one message every ``state_every`` ticks with the program's state
  columns (handle and tool forces and positions, compensator outputs; names carry units);
- ``/<side>/link``: the link's statistics (one-way delay percentiles, loss, reordering,
  sent, watchdog state) at ``status_rate_hz``;
- ``/<side>/events``: each safety event (watchdog trips and resyncs, the node's safety layer,
  tool stops, peer presence) as it is seen at the status rate;
- ``/<side>/config``: the validated configuration of the run, once at the start;
- ``/<side>/summary``: the run summary, once at the end (absent in a killed run's file);
- the slave adds ``/slave/workpiece`` (block layout, once) and ``/slave/clay`` (the height
  map, downsampled, at the start and the end).

Log times are CLOCK_REALTIME ns: the loop's start on that clock plus the tick's offset on the
runner's monotonic clock.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from haptic.common.records.recorder import McapRecorder


class RunRecording:
    """One program's recording: call :meth:`start` when the loop's clocks are anchored, then
    :meth:`state` every tick, :meth:`status_due`/:meth:`status` at the status rate, and
    :meth:`close` at the end."""

    def __init__(self, path: str | Path, side: str, state_fields: Sequence[str],
                 period_s: float, *, state_every: int = 1, status_rate_hz: float = 10.0,
                 queue_size: int | None = None) -> None:
        if state_every < 1:
            raise ValueError(f"state_every must be >= 1 (got {state_every})")
        kwargs = {} if queue_size is None else {"queue_size": queue_size}
        self.recorder = McapRecorder(path, side, **kwargs)
        self.side = side
        self.state_every = state_every
        self.status_every = max(1, round(1.0 / (status_rate_hz * period_s)))
        self.topic_state = f"/{side}/state"
        self.topic_link = f"/{side}/link"
        self.topic_events = f"/{side}/events"
        self.topic_config = f"/{side}/config"
        self.topic_summary = f"/{side}/summary"
        self.recorder.add_channel(self.topic_state, state_fields)
        for topic in (self.topic_link, self.topic_events, self.topic_config, self.topic_summary):
            self.recorder.add_channel(topic)
        self._offset_ns = 0
        self.recorder.open()

    def start(self, realtime_start_ns: int, perf_start_ns: int,
              config: dict[str, Any] | None) -> None:
        """Anchor the log times and record the configuration."""
        self._offset_ns = realtime_start_ns - perf_start_ns
        if config is not None:
            self.recorder.record(self.topic_config, realtime_start_ns, config)

    def log_time_ns(self, now_ns: int) -> int:
        """The CLOCK_REALTIME log time of a runner-clock instant."""
        return now_ns + self._offset_ns

    def state(self, tick: int, now_ns: int, values: Sequence[float]) -> None:
        """One tick's state (kept every ``state_every`` ticks)."""
        if tick % self.state_every == 0:
            self.recorder.record(self.topic_state, now_ns + self._offset_ns, values)

    def status_due(self, tick: int) -> bool:
        """Whether this tick records the link statistics and new events."""
        return tick % self.status_every == 0

    def status(self, now_ns: int, link_figures: dict[str, Any],
               new_events: Sequence[dict[str, Any]]) -> None:
        """The link's statistics and the events seen since the last call (dicts with
        ``time_s`` relative to the loop start)."""
        log_time = now_ns + self._offset_ns
        self.recorder.record(self.topic_link, log_time, link_figures)
        for event in new_events:
            self.recorder.record(self.topic_events, log_time, event)

    def record(self, topic: str, log_time_ns: int, values: Any) -> None:
        """Any other message (channels added with :meth:`add_channel`)."""
        self.recorder.record(topic, log_time_ns, values)

    def add_channel(self, topic: str, fields: Sequence[str] | None = None) -> None:
        self.recorder.add_channel(topic, fields)

    def close(self, log_time_ns: int, summary: dict[str, Any] | None) -> dict[str, Any]:
        """Record the summary, close the file; returns the recorder's figures."""
        if summary is not None:
            self.recorder.record(self.topic_summary, log_time_ns, summary)
        self.recorder.close()
        return self.recorder.figures()
