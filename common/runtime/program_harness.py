"""What ``haptic-master`` and ``haptic-slave`` share around their tick: waiting for the peer,
the real-time runner, the recording's start and status, the display feed's pacing, the live
status line and the run's summary. Each program keeps only its own tick (master/tick.py,
slave_sim/tick.py), its stages on the one tick driver (common/runtime/tick_driver.py) and its
own telemetry columns (docs/architecture.md, "one tick").

One run, in order::

    harness = ProgramHarness("haptic-slave", "master", options, link, period_s, recording)
    status = harness.wait_for_peer(peer_wait_s, signals)   # None: the peer came
    harness.start()                                         # the run's time origin
    harness.attach_display(display)                         # optional
    run = harness.run(driver, status_text, signals, on_stop)  # the one tick driver
    summary = harness.summary(run, watchdog, max_force_N, event_lists, **extra)
    harness.finish(summary)                                 # recording, JSON, stderr

Their shared command-line options are :func:`add_networked_options`.

It does no control work and imports no CAN stack, Warp or program package.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from haptic.common.config import ConfigError
from haptic.common.records.run_recording import RunRecording
from haptic.common.runtime.display import DisplayPublisher, EventCursor
from haptic.common.runtime.display_backoff import DisplayBackoff
from haptic.common.runtime.runner import LeadFunction, RealTimeRunner, RunStats, StopSignals
from haptic.common.runtime.runner_config import prioritise_zenoh_threads
from haptic.common.runtime.summary import format_summary, make_summary, write_json_summary
from haptic.common.runtime.tick_driver import TickDriver
from haptic.common.runtime.watchdog import PeerWatchdog
from haptic.common.wire.link import Link

#: Rate of the status figures into the recording and the display feed, Hz.
STATUS_RATE_HZ = 10.0


class ProgramHarness:
    """The shared frame of one networked program (see the module docstring).

    ``program``: its name for messages (``haptic-master``); ``peer``: the other side's name
    (``slave``); ``options``: the run options (``RunOptions``: ``runner``, ``duration_s``,
    ``show_status``, ``json_summary``, ``config``); ``link``: the open link; ``period_s``:
    Ts, s; ``recording``: the run's MCAP recording or ``None``.
    """

    def __init__(self, program: str, peer: str, options: Any, link: Link, period_s: float,
                 recording: RunRecording | None = None) -> None:
        self.program = program
        self.peer = peer
        self.options = options
        self.link = link
        self.period_s = period_s
        self.recording = recording
        self.display: DisplayPublisher | None = None
        self.view_every = 1
        self.status_every = max(1, round(1.0 / (STATUS_RATE_HZ * period_s)))
        self.cursor = EventCursor()
        self.zenoh_threads: dict[str, object] = {}
        self.realtime_start_ns = 0
        self.perf_start_ns = 0
        self.runner: RealTimeRunner | None = None
        self.link_summary: dict[str, Any] = {}
        self.presence: list[dict[str, Any]] = []

    def say(self, text: str) -> None:
        """One line on stderr, prefixed with the program's name."""
        print(f"{self.program}: {text}", file=sys.stderr, flush=True)

    def wait_for_peer(self, peer_wait_s: float | None, signals: StopSignals,
                      preface: str = "") -> int | None:
        """Wait for the peer (``peer_wait_s``: at most this long, s; ``None``: until stopped).
        Returns ``None`` when it came (Zenoh's threads are then prioritised as configured),
        otherwise the exit status: 0 when stopped first, 1 when it did not come in time."""
        config = self.link.config
        marker = self.unauthenticated_marker
        self.say(f"{preface}waiting for the {self.peer} on {config.key_prefix} (listen "
                 f"{','.join(config.listen) or '-'}, connect {','.join(config.connect) or '-'})"
                 + (f"; {marker}: anyone who reaches the session can drive the handle and "
                    "the tool" if marker else ""))
        if not self.link.wait_for_peer(peer_wait_s, lambda: signals.requested):
            if signals.requested:
                self.say(f"stopped before the {self.peer} came")
                return 0
            hint = ("; Zenoh admits only a peer with the same session key: check both "
                    "sides' --session-key" if config.transport_key is not None else "")
            self.say(f"no {self.peer} after {peer_wait_s:g} s{hint}")
            return 1
        self.zenoh_threads.update(prioritise_zenoh_threads(self.options.runner))
        return None

    def start(self) -> None:
        """The run's time origin (wall clock and the runner's clock); the recording starts."""
        self.realtime_start_ns = time.time_ns()
        self.perf_start_ns = time.perf_counter_ns()
        if self.recording is not None:
            self.recording.start(self.realtime_start_ns, self.perf_start_ns,
                                 self.options.config)

    def attach_display(self, display: DisplayPublisher | None) -> None:
        """Publish to the live view through ``display`` (started by the caller), with the
        loop's counts; with ``[runner] display_backoff`` its rates back off while the loop
        overruns (common/runtime/display_backoff.py)."""
        self.display = display
        if display is not None:
            self.view_every = display.state_every(self.period_s)
            display.follow_loop(self.loop_counts, DisplayBackoff()
                                if self.options.runner.display_backoff else None)

    def loop_counts(self) -> tuple[int, int]:
        """The loop's ticks stepped and overruns so far (0, 0 before it runs); any thread."""
        runner = self.runner
        if runner is None:
            return 0, 0
        return runner.steps, runner.overruns

    def time_s(self, now_ns: int) -> float:
        """A tick's time since :meth:`start`, s."""
        return (now_ns - self.perf_start_ns) * 1e-9

    def offer_state(self, tick: int, state: Callable[[], dict[str, Any]]) -> None:
        """Offer ``state()`` to the display at its rate (not built on the other ticks, nor
        while no viewer subscribes to it)."""
        display = self.display
        if display is not None and tick % self.view_every == 0 and display.state_watched:
            display.offer_state(state())

    def status(self, tick: int, now_ns: int, watchdog: PeerWatchdog,
               event_lists: Sequence[list[Any]], **figures: Any) -> None:
        """At :data:`STATUS_RATE_HZ`: the link's figures, the watchdog's state and trips,
        ``figures`` and the events new in ``event_lists``, into the recording and the
        display (nothing is built while neither records nor has a viewer)."""
        if tick % self.status_every or (self.recording is None and (
                self.display is None or not self.display.status_watched)):
            return
        values = self.link.summary()
        values["watchdog_state"] = watchdog.state.value
        values["watchdog_trips"] = watchdog.trips
        values.update(figures)
        new_events = self.cursor.new(event_lists)
        if self.recording is not None:
            self.recording.status(now_ns, values, new_events)
        if self.display is not None:
            self.display.offer_status(values, new_events)

    @property
    def unauthenticated_marker(self) -> str:
        """``UNAUTHENTICATED (--insecure)`` when the user let the session run with neither a
        session key nor mutual TLS (common/wire/protected_mode.py), else empty."""
        protection = getattr(self.link, "protection", None)
        return protection.marker if protection is not None else ""

    def status_line(self, watchdog: PeerWatchdog, text: str) -> str:
        """The live status line: the unauthenticated marker (if any), the link's delay and
        loss, the watchdog's state, ``text`` (this side's figures)."""
        stats = self.link.stats()
        marker = self.unauthenticated_marker
        return ((f"{marker}  " if marker else "")
                + f"link p50 {stats.one_way_delay_p50_s * 1e3:.3f} ms  loss "
                f"{stats.loss_ratio * 100:.2f} %  {watchdog.state.value}  {text}")

    def run(self, driver: TickDriver, status_text: Callable[[], str], signals: StopSignals,
            on_stop: Callable[[], None], lead: LeadFunction | None = None,
            lead_s: float = 0.0, before_loop: Callable[[], None] | None = None) -> RunStats:
        """The real-time runner over ``driver``'s ticks for the run's duration (or until
        stopped); :attr:`runner` is the runner while it runs, and the schedule shifts the
        driver's sides ask for go to it (``TickDriver.follow``). On every
        way out ``on_stop()`` puts the side in its safe state and tells the peer, then the
        link's figures are kept (:meth:`collect_link`). ``status_text()``: this side's part
        of the live status line; ``lead``/``lead_s``: the runner's call ``lead_s`` (s) before
        each tick (the master's early SYNC). ``before_loop()``: the program's last work before
        the first tick, on the loop's CPU under its scheduling once the heap is frozen (the
        first ticks then find what it touched in that CPU's caches); then the peer's backlog
        is dropped (``Link.discard_received``)."""
        options = self.options
        link = self.link

        def prepare() -> None:
            if before_loop is not None:
                before_loop()
            link.discard_received()

        self.runner = RealTimeRunner(
            self.period_s, driver.step, duration_s=options.duration_s, max_steps=options.max_steps,
            spin_s=options.runner.spin_s, freeze_heap=True, prepare=prepare,
            realtime=options.runner.realtime, status=status_text,
            show_status=options.show_status, stop_signals=signals, lead=lead, lead_s=lead_s)
        driver.follow(self.runner.shift_schedule)
        try:
            return self.runner.run()
        finally:
            on_stop()
            self.collect_link()

    def collect_link(self) -> None:
        """The link's figures and its peer's comings and goings (before the link closes)."""
        self.link_summary = self.link.summary()
        self.presence = [event.as_dict() for event in self.link.presence_events]
        if self.display is not None:
            self.display.stop()

    def summary(self, run: RunStats, watchdog: PeerWatchdog, max_force_N: float,
                event_lists: Sequence[Sequence[Any]], **extra: Any) -> dict[str, Any]:
        """The run's summary (common/runtime/summary.py): the runner's and the link's figures, the
        watchdog's, every event in time order (the peer's presence included), ``extra``."""
        origin_s = self.realtime_start_ns * 1e-9
        events = [event.as_dict() if hasattr(event, "as_dict") else event
                  for source in event_lists for event in source]
        events += [{**event, "time_s": event["time_s"] - origin_s} for event in self.presence]
        events.sort(key=lambda event: event["time_s"])
        summary = make_summary(
            run.as_summary(), self.link_summary, max_abs_force_N=max_force_N,
            watchdog_trips=watchdog.trips, events=events, side=self.link.config.side,
            watchdog_state=watchdog.state.value, loop_start_time_s=origin_s,
            **self.zenoh_threads, **extra)
        if self.display is not None:
            summary.update(self.display.figures)
        return summary

    def finish(self, summary: dict[str, Any],
               before_close: Callable[[RunRecording, int], None] | None = None) -> None:
        """Close the recording (``before_close(recording, end_ns)`` writes last records),
        write ``--json-summary`` and print the summary on stderr."""
        if self.recording is not None:
            end_ns = time.time_ns()
            if before_close is not None:
                before_close(self.recording, end_ns)
            summary.update(self.recording.close(end_ns, summary))
        if self.options.json_summary is not None:
            write_json_summary(self.options.json_summary, summary)
        marker = self.unauthenticated_marker
        self.say(format_summary(summary) + (
            f"\nsession {marker}: nothing authenticated the peer's messages (reachable: "
            f"{', '.join(summary.get('link_reachable') or []) or 'loopback only'})"
            if marker else ""))


@contextmanager
def recording_for(path: str | None, side: str, columns: Sequence[str], period_s: float,
                  state_every: int) -> Iterator[RunRecording | None]:
    """The run's MCAP recording at ``path`` (``None``: no recording), closed properly on
    every way out (common/records/run_recording.py)."""
    recording = None if not path else RunRecording(path, side, columns, period_s,
                                                   state_every=state_every)
    try:
        yield recording
    finally:
        if recording is not None:
            recording.close(time.time_ns(), None)


def add_networked_options(parser: argparse.ArgumentParser, peer: str, out_help: str,
                          sync_tolerance_m: float) -> argparse._ArgumentGroup:
    """The networked programs' shared options (one spelling in both): ``--out DIR``
    (``out_help``: what is written there), ``--peer-wait S``, ``--sync-tolerance M``
    (default ``sync_tolerance_m``, m) and ``--trace-every N``. Returns the group, for the
    program's own options."""
    group = parser.add_argument_group("networked run")
    group.add_argument("--out", metavar="DIR", type=Path, help=out_help)
    group.add_argument("--peer-wait", metavar="S", type=float,
                       help=f"give up (exit 1) when no {peer} appears within S s "
                       "(default: wait)")
    group.add_argument("--sync-tolerance", metavar="M", type=float, default=sync_tolerance_m,
                       help="resync: |tool - Ah1 handle| below this on both axes, m "
                       f"(default {sync_tolerance_m:g})")
    group.add_argument("--trace-every", metavar="N", type=int, default=10,
                       help="keep every Nth tick in the trace (default 10)")
    return group


def check_networked_options(args: argparse.Namespace) -> None:
    """The shared options' bounds (raises :class:`ConfigError` naming the option)."""
    if not args.sync_tolerance > 0.0:
        raise ConfigError("--sync-tolerance", f"must be > 0 m (got {args.sync_tolerance})")
    if args.trace_every < 1:
        raise ConfigError("--trace-every", f"must be >= 1 (got {args.trace_every})")
    if args.record_every < 1:
        raise ConfigError("--record-every", f"must be >= 1 (got {args.record_every})")
