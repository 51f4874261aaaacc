"""``haptic-replay FILE [FILE ...]``: a recorded run's summary and the paper-style plots.

For each MCAP file written with ``--record`` (the master's, the slave's, or both) it prints
what the file holds (side, complete or cut short, span, messages per channel, the recorder's
drops, the safety events, the link's last statistics and, from the slave's state, the cut's
duration, mean force and speed, on the samples' clock as the slave reports them) and writes
PNGs into ``--out``:

- ``force_time.png``: forces against time (tool force ft and received handle force fh at the
  slave; handle force and felt force at the master);
- ``velocity_position.png``: tool velocity against tool position (x);
- ``force_position.png``: tool force against tool position (x);
- ``clay.png``: the workpiece height map at the end with the tool path.

``--view`` replays the recording into the live view (``haptic-view``) instead, at ``--speed``
times real time.

Exit status: 0 when every file was read (complete, or cut short by a killed writer); 1 when a
file cannot be opened, is not MCAP, or holds no message of a master's or slave's recording;
3 when a file is damaged inside (read up to the damage, the summary printed and the error
named); 2 for bad arguments.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from haptic.common.records.recording import Recording, read_recording
from haptic.common.runtime.console import quiet_on_closed_stdout, script_description


def side_of(recording: Recording) -> str:
    """``master`` or ``slave`` (from the metadata, else from the channel names)."""
    side = recording.metadata.get("recorder", {}).get("side")
    if side:
        return side
    for topic in recording.messages:
        return topic.strip("/").split("/")[0]
    return "unknown"


def summarize(recording: Recording) -> dict[str, Any]:
    """The figures of one recording (JSON-safe)."""
    side = side_of(recording)
    counts = recording.counts()
    times = [t for items in recording.messages.values() for t, _ in items]
    summary: dict[str, Any] = {
        "file": str(recording.path), "side": side, "complete": recording.complete,
        "status": recording.status, "read_error": recording.error or None,
        "skipped_messages": recording.skipped, "messages": counts,
        "span_s": (max(times) - min(times)) * 1e-9 if times else 0.0,
    }
    meta = recording.metadata.get("recorder")
    if meta:
        summary["recorder_written"] = _count(meta.get("written"))
        summary["recorder_dropped"] = _count(meta.get("dropped"))
        summary["recorder_max_queue_depth"] = _count(meta.get("max_queue_depth"))
    events = [m for _, m in recording.messages.get(f"/{side}/events", [])]
    summary["events"] = events
    link = recording.last(f"/{side}/link")
    if link:
        summary["link"] = {k: link.get(k) for k in (
            "link_one_way_delay_p50_s", "link_one_way_delay_p99_s", "loss_ratio", "link_received",
            "link_sent", "watchdog_state", "watchdog_trips") if k in link}
    state = recording.columns(f"/{side}/state")
    if "time_s" not in state:  # a state channel without its clock: nothing to time
        state = {}
    if state:
        summary["state_rate_hz"] = (
            (state["time_s"].size - 1) / (state["time_s"][-1] - state["time_s"][0])
            if state["time_s"].size > 1 and state["time_s"][-1] > state["time_s"][0] else 0.0)
        for name in ("tool_force_x_N", "handle_force_x_N", "felt_force_x_N"):
            if name in state:
                values = state[name][np.isfinite(state[name])]
                if values.size:
                    summary[f"max_abs_{name}"] = float(np.abs(values).max())
    if side == "slave" and state and not (missing := [
            name for name in _CUT_COLUMNS if name not in state]):
        summary.update(cut_figures(state))
    elif side == "slave" and state:
        summary["cut_missing_columns"] = missing
    run_summary = recording.last(f"/{side}/summary")
    if run_summary:
        summary["run"] = {k: run_summary.get(k) for k in (
            "rate_hz", "overruns", "period_p99_error_s", "stop_reason", "watchdog_trips",
            "removed_volume_m3") if k in run_summary}
    return summary


def cut_figures(state: dict[str, np.ndarray]) -> dict[str, Any]:
    """The cut's figures of a slave's recorded state, timed on the samples' own clock
    (``sample_time_s``: node steps x Ts) as the slave's summary times them: a master that
    falls behind real time slows the cut on the wall clock, not on the samples'. A recording
    without that column (written before it was recorded) is timed on the wall clock
    (``time_s``); ``cut_clock`` says which ("sample" or "wall")."""
    from haptic.common.records.cutting import cutting_figures, steady_cut_fields

    trace = dict(state)
    trace["forces_enabled"] = state["running"]
    sampled = "sample_time_s" in state and state["sample_time_s"].size == state["time_s"].size
    if sampled:
        trace["time_s"] = state["sample_time_s"]
    return {**cutting_figures(trace), **steady_cut_fields(trace),
            "cut_clock": "sample" if sampled else "wall"}


#: The slave state's columns the cut's figures need.
_CUT_COLUMNS = ("time_s", "running", "cutting", "tool_force_x_N", "tool_force_y_N",
                "tool_velocity_x_m_s", "tool_velocity_y_m_s", "tool_position_x_m",
                "tool_position_y_m", "handle_force_x_N")
_STATUS_TEXT = {"complete": "complete", "cut short": "cut short (no footer)",
                "damaged": "damaged"}


def _count(value: Any) -> int | None:
    """A count from the recorder's metadata (text), None when it is not one."""
    try:
        return int(value)
    except (TypeError, ValueError):
        return None


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def format_text(summary: dict[str, Any]) -> str:
    """The summary as a few lines for the terminal."""
    lines = [f"{summary['file']}: {summary['side']}, {_STATUS_TEXT[summary['status']]}, "
             f"{summary['span_s']:.2f} s"]
    if summary["read_error"]:
        lines.append(f"  read error: {summary['read_error']}")
    lines.append("  messages: " + ", ".join(f"{t} {n}" for t, n in summary["messages"].items()))
    if summary["skipped_messages"]:
        lines.append(f"  skipped: {summary['skipped_messages']} messages that are not JSON "
                     "objects")
    if summary.get("cut_missing_columns"):
        lines.append("  cut: no figures, the state lacks "
                     + ", ".join(summary["cut_missing_columns"]))
    if "recorder_dropped" in summary:
        lines.append(f"  recorder: written {summary['recorder_written']}, dropped "
                     f"{summary['recorder_dropped']}, max queue depth "
                     f"{summary['recorder_max_queue_depth']}")
    if "link" in summary:
        link = summary["link"]
        p50, p99 = link.get("link_one_way_delay_p50_s"), link.get("link_one_way_delay_p99_s")
        loss = link.get("loss_ratio")
        if _is_number(p50) and _is_number(p99) and _is_number(loss):
            lines.append(f"  link: one-way delay p50 {p50 * 1e3:.3f} ms, p99 {p99 * 1e3:.3f} "
                         f"ms, loss {loss * 100:.2f} %, watchdog {link.get('watchdog_state')} "
                         f"(trips {link.get('watchdog_trips')})")
    if summary.get("cut_mean_force_N") is not None:
        clock = ("" if summary.get("cut_clock") == "sample" else
                 " (on the wall clock: the recording holds no sample clock)")
        lines.append(f"  cut: {summary['cutting_time_s']:.2f} s in the clay, mean |ft| "
                     f"{summary['cut_mean_force_N']:.3f} N, mean speed "
                     f"{summary['cut_mean_speed_m_s'] * 1e3:.1f} mm/s{clock}")
    for event in summary["events"]:
        time_s = event.get("time_s")
        stamp = f"{time_s:8.3f} s" if _is_number(time_s) else "       ?"
        lines.append(f"  event {stamp}  {event.get('kind')}: {event.get('reason', '')}")
    return "\n".join(lines)


def haptic_topics(recording: Recording) -> list[str]:
    """The recording's topics of a master's or a slave's run that hold messages."""
    return [topic for topic, items in recording.messages.items()
            if items and topic.startswith(("/master/", "/slave/"))]


def _plot_forces_against_time(plt: Any, s_state: dict[str, np.ndarray],
                              m_state: dict[str, np.ndarray], path: Path) -> Path:
    """The slave's tool forces and received handle force and the master's handle and felt
    forces (N) against time (s), whichever side was recorded."""
    figure, axes = plt.subplots(figsize=(9, 4.5), dpi=110)
    if s_state:
        axes.plot(s_state["time_s"], s_state["tool_force_x_N"], label="ft x (slave)")
        axes.plot(s_state["time_s"], s_state["tool_force_y_N"], label="ft y (slave)")
        axes.plot(s_state["time_s"], s_state["handle_force_x_N"], label="fh x received",
                  alpha=0.7)
    if m_state:
        axes.plot(m_state["time_s"], m_state["handle_force_x_N"], label="fh x (master)",
                  alpha=0.7)
        axes.plot(m_state["time_s"], m_state["felt_force_x_N"], label="felt ft x (master)",
                  alpha=0.7)
    axes.set_xlabel("time (s)")
    axes.set_ylabel("force (N)")
    axes.set_title("Forces against time")
    axes.grid(True, alpha=0.3)
    axes.legend(fontsize=8)
    return _save(figure, path)


def _plot_tool_against_position(plt: Any, s_state: dict[str, np.ndarray],
                                out: Path) -> list[Path]:
    """The tool's velocity (mm/s) and force (N) against its x position (mm): two PNGs."""
    x_mm = s_state["tool_position_x_m"] * 1e3
    figure, axes = plt.subplots(figsize=(9, 4.5), dpi=110)
    axes.plot(x_mm, s_state["tool_velocity_x_m_s"] * 1e3, linewidth=0.8)
    axes.set_xlabel("tool position x (mm)")
    axes.set_ylabel("tool velocity x (mm/s)")
    axes.set_title("Velocity against position")
    axes.grid(True, alpha=0.3)
    written = [_save(figure, out / "velocity_position.png")]

    figure, axes = plt.subplots(figsize=(9, 4.5), dpi=110)
    axes.plot(x_mm, s_state["tool_force_x_N"], linewidth=0.8, label="ft x")
    axes.plot(x_mm, np.hypot(s_state["tool_force_x_N"], s_state["tool_force_y_N"]),
              linewidth=0.8, label="|ft|")
    axes.set_xlabel("tool position x (mm)")
    axes.set_ylabel("tool force (N)")
    axes.set_title("Force against position")
    axes.grid(True, alpha=0.3)
    axes.legend(fontsize=8)
    written.append(_save(figure, out / "force_position.png"))
    return written


def _plot_workpiece(plt: Any, plan: tuple[np.ndarray, tuple[float, ...]],
                    layout: dict[str, Any], s_state: dict[str, np.ndarray], path: Path) -> Path:
    """The clay's heights (mm) at the end over x and y (mm), each block outlined and named
    with its damping (N s/m), and the tool's path when the slave's state was recorded."""
    heights, (x0, x1, y0, y1) = plan
    aspect = (y1 - y0) / (x1 - x0)
    figure, axes = plt.subplots(figsize=(10, max(2.5, 10 * aspect + 1.0)), dpi=110)
    image = axes.imshow(heights, origin="lower", extent=[x0, x1, y0, y1], cmap="viridis",
                        interpolation="nearest")
    figure.colorbar(image, ax=axes, label="clay height (mm)", shrink=0.8)
    ids = np.array(layout["block_id"])
    xs = np.linspace(x0, x1, ids.shape[1] + 1)[:-1] + (x1 - x0) / ids.shape[1] / 2
    ys = np.linspace(y0, y1, ids.shape[0] + 1)[:-1] + (y1 - y0) / ids.shape[0] / 2
    for index, name in enumerate(layout["block_names"]):
        mask = (ids == index).astype(float)
        if mask.any() and not mask.all():
            axes.contour(xs, ys, mask, levels=[0.5], colors="white", linewidths=0.8)
        if mask.any():
            row, col = np.argwhere(ids == index).mean(axis=0)
            axes.text(xs[int(col)], ys[int(row)],
                      f"{name}\n{layout['block_damping_N_s_per_m'][index]:g} N s/m",
                      color="white", ha="center", va="center", fontsize=7)
    if s_state:
        axes.plot(s_state["tool_position_x_m"] * 1e3, s_state["tool_position_y_m"] * 1e3,
                  color="red", linewidth=1.0, label="tool path")
        axes.legend(fontsize=8, loc="upper right")
    axes.set_xlabel("x (mm)")
    axes.set_ylabel("y (mm)")
    axes.set_title("Workpiece at the end of the run, with the tool path")
    return _save(figure, path)


def write_plots(recordings: Sequence[Recording], out: Path) -> list[Path]:
    """The paper-style PNGs of the recordings into ``out``; returns the paths written."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    by_side = {side_of(r): r for r in recordings}
    slave = by_side.get("slave")
    master = by_side.get("master")
    s_state = _with_columns(slave.columns("/slave/state") if slave else {}, _SLAVE_PLOTTED)
    m_state = _with_columns(master.columns("/master/state") if master else {}, _MASTER_PLOTTED)
    if s_state or m_state:
        written.append(_plot_forces_against_time(plt, s_state, m_state,
                                                 out / "force_time.png"))
    if s_state:
        written += _plot_tool_against_position(plt, s_state, out)
    layout = slave.last("/slave/workpiece") if slave else None
    clay = slave.last("/slave/clay") if slave else None
    plan = _clay_plan(layout, clay)
    if plan is not None:
        written.append(_plot_workpiece(plt, plan, layout, s_state, out / "clay.png"))
    return written


#: The state columns the plots draw (a state without one of them is not plotted).
_SLAVE_PLOTTED = ("time_s", "tool_force_x_N", "tool_force_y_N", "handle_force_x_N",
                  "tool_position_x_m", "tool_position_y_m", "tool_velocity_x_m_s")
_MASTER_PLOTTED = ("time_s", "handle_force_x_N", "felt_force_x_N")


def _with_columns(state: dict[str, np.ndarray], names: Sequence[str]) -> dict[str, np.ndarray]:
    """``state`` when it has every column of ``names``, else empty."""
    return state if all(name in state for name in names) else {}


def _clay_plan(layout: Any, clay: Any) -> tuple[np.ndarray, tuple[float, ...]] | None:
    """The clay map (mm) and its extent (x0, x1, y0, y1 in mm) when the recorded layout and
    map make a picture: a 2-D map of numbers, ranges of two increasing finite numbers, and
    the layout's block ids, names and dampings of matching shapes; else None (no plot)."""
    if not isinstance(layout, dict) or not isinstance(clay, dict):
        return None
    try:
        heights = np.array(clay["heights_mm"], float)
        (x0, x1), (y0, y1) = (np.array(layout[key], float) * 1e3
                              for key in ("x_range_m", "y_range_m"))
        ids = np.array(layout["block_id"])
        names, dampings = layout["block_names"], layout["block_damping_N_s_per_m"]
    except (KeyError, TypeError, ValueError):
        return None
    extent = (float(x0), float(x1), float(y0), float(y1))
    if (heights.ndim != 2 or not heights.size or ids.ndim != 2 or not ids.size
            or min(ids.shape) < 2 or ids.dtype.kind not in "iu" or not isinstance(names, list)
            or not isinstance(dampings, list) or len(names) != len(dampings)
            or not all(_is_number(value) for value in dampings)
            or not all(np.isfinite(extent)) or not (x1 > x0 and y1 > y0)):
        return None
    return heights, extent


def _save(figure: Any, path: Path) -> Path:
    import matplotlib.pyplot as plt

    figure.tight_layout()
    figure.savefig(path)
    plt.close(figure)
    return path


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="haptic-replay", description=script_description(__doc__),
                                     allow_abbrev=False)
    parser.add_argument("files", nargs="+", metavar="FILE", help="MCAP recordings (--record)")
    parser.add_argument("--out", metavar="DIR", type=Path, default=Path("out/replay"),
                        help="where the PNGs go (default out/replay)")
    parser.add_argument("--no-plots", action="store_true", help="print the summary only")
    parser.add_argument("--json", action="store_true", help="print the summaries as JSON")
    parser.add_argument("--view", action="store_true",
                        help="replay into the live view (haptic-view) instead")
    parser.add_argument("--speed", metavar="X", type=float, default=1.0,
                        help="--view: times real time (default 1)")
    parser.add_argument("--port", metavar="N", type=int, default=8765,
                        help="--view: HTTP port on localhost (default 8765)")
    return parser


@quiet_on_closed_stdout
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; the exit status is the module docstring's."""
    args = build_parser().parse_args(argv)
    if not args.speed > 0.0:
        print("haptic-replay: --speed: must be > 0", file=sys.stderr)
        return 2
    recordings = []
    for name in args.files:
        try:
            recording = read_recording(name)
        except (OSError, ValueError) as error:
            print(f"haptic-replay: {name}: {error}", file=sys.stderr)
            return 1
        if not haptic_topics(recording):
            topics = ", ".join(recording.messages) or "none"
            why = f"; {recording.error}" if recording.error else ""
            print(f"haptic-replay: {name}: no message of a master's or slave's recording "
                  f"({recording.status}, topics: {topics}{why})", file=sys.stderr)
            return 1
        recordings.append(recording)
    damaged = [r for r in recordings if r.damaged]
    for recording in damaged:
        print(f"haptic-replay: {recording.path}: damaged, read up to {recording.error}",
              file=sys.stderr)
    if args.view:
        from haptic.view.replay.playback import replay_into_view

        status = replay_into_view(recordings, port=args.port, speed=args.speed)
        return status or (3 if damaged else 0)
    summaries = [summarize(r) for r in recordings]
    plots: list[Path] = [] if args.no_plots else write_plots(recordings, args.out)
    if args.json:
        from haptic.common.runtime.summary import json_safe

        print(json.dumps(json_safe({"recordings": summaries,
                                    "plots": [str(p) for p in plots]}), indent=2))
    else:
        for summary in summaries:
            print(format_text(summary))
        for path in plots:
            print(f"wrote {path}")
    return 3 if damaged else 0


if __name__ == "__main__":
    sys.exit(main())
