"""``haptic-session``: one teleoperation session on this machine, end to end.

Starts ``haptic-slave`` and ``haptic-master`` as two child processes talking over Zenoh on
loopback (a fresh key prefix and TCP port, so sessions and tests never cross), by default the
paper's constant-cutting-rate experiment: simulated rig, the regulating operator holding a
3.6 N cutting force, the ``constant-rate`` clay scenario, 4 s. Waits for both, then prints a
combined summary (rates, period error, overruns, link delay and loss, forces, the cut, the
watchdog) and writes a report directory (``--out``, default ``out/session``):

- ``report.md``: the combined summary and both JSON summaries;
- ``master.json``, ``slave.json``: the programs' ``--json-summary`` files;
- ``clay.png``, ``clay.npz``: the cut workpiece with the tool path;
- ``master_trace.npz``, ``slave_trace.npz``: every 10th tick of each side;
- ``session.png``: handle and tool force against time, tool velocity against position.

On a machine with two CPUs or more the session gives each loop a CPU of its own
(``--cpu-layout split``, the default; :func:`session_cpu_args`): the master's loop and its
emulated drives on the last CPU, the slave's loop under SCHED_FIFO on the first, every other
thread (Zenoh's, the displays') off the master's CPU. ``--cpu-layout free`` leaves every
thread where the kernel puts it and the ``[runner]`` table of ``--config`` as it is. (The
loop benchmark's layouts are others: common/runtime/cpu_layout.py.)

Children are ended by their own PID (SIGTERM, then SIGKILL after a grace period) on timeout
or Ctrl-C, and always reaped. Exit status 0 when both programs exited 0 and wrote their
summaries; otherwise the status of the first program to end on its own with a non-zero status
(e.g. 3 for the analysis refusal; 1 for a signal), or 1.
"""

from __future__ import annotations

import argparse
import atexit
import json
import math
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import uuid
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from haptic.common.launch.guidance import (
    expected_duration_line,
    kernels_cached,
    missed_guidance_lines,
    warp_kernel_cache_dir,
)
from haptic.common.ros2.options import add_ros2_options, forwarded_ros2_args
from haptic.common.runtime.cli_options import add_retired_delay_option
from haptic.common.runtime.console import script_description
from haptic.common.runtime.cpu_layout import (
    LOOPS_ON_SEPARATE_CPUS,
    SESSION_LAYOUTS,
    SESSION_UNPINNED,
    layout_names,
)
from haptic.common.runtime.machine import usable_cpu_count, usable_cpus
from haptic.common.runtime.summary import finite_figure, loop_cpu_text
from haptic.common.wire.auth import write_key_file
from haptic.common.wire.ports import free_port

DEFAULT_OPERATOR = "regulate:fx=3.6,onset=0.2,max=5"
#: Seconds a child gets after SIGTERM before SIGKILL: the slave, stopped once the master is
#: done, then writes its summary, trace and clay map, which takes several seconds on a loaded
#: machine of few CPUs (a few seconds' grace killed it there mid-write).
TERM_GRACE_S = 15.0
#: Start-up allowance on top of the duration (Python, Warp and Zenoh start, the peer wait), s.
START_ALLOWANCE_S = 40.0
#: The master steps the session's duration in rig time (``--rig-time``), so the scripted
#: scenario runs to its end however loaded the machine is; a run this many times slower than
#: real time still finishes (the slave's wall-time bound and the session's deadline).
SLOWDOWN_ALLOWANCE = 8.0


#: The largest position gap |yt - Ah1 yh| at the end of a session, m: the handle stops where
#: the tool does.
GAP_TARGET_M = 0.001
#: The session's CPU layouts (:func:`session_cpu_args`; common/runtime/cpu_layout.py).
CPU_LAYOUTS = layout_names(SESSION_LAYOUTS)
#: The slave loop's SCHED_FIFO priority in the split layout (refused without CAP_SYS_NICE:
#: then normal scheduling and a warning).
SPLIT_SLAVE_PRIORITY = 40


def session_cpu_args(layout: str, cpus: Sequence[int]) -> tuple[list[str], list[str]]:
    """The master's and the slave's run options of a CPU layout on ``cpus`` (the CPUs this
    process may use). ``split`` on two CPUs or more: the master's loop on the last CPU, where
    its emulated drives follow it (master/simulated_rig/rig_emulator.py: they answer the SYNC while
    its
    loop sleeps); the slave's loop under SCHED_FIFO on the first; every other thread of both
    programs on the CPUs but the master's (the first alone on two): neither loop then waits
    for a CPU that another thread holds (what it does for the loop targets on two CPUs:
    docs/programs.md). ``free``, or one CPU: nothing."""
    if layout not in CPU_LAYOUTS:
        raise ValueError(f"cpu layout must be one of {', '.join(CPU_LAYOUTS)} (got {layout!r})")
    cpus = sorted(set(cpus))
    if layout == SESSION_UNPINNED.name or len(cpus) < 2:
        return [], []
    master_cpu, slave_cpu = cpus[-1], cpus[0]
    others = ",".join(str(cpu) for cpu in (cpus[1:-1] if len(cpus) > 2 else cpus[:1]))
    return (["--loop-cpus", str(master_cpu), "--other-cpus", others],
            ["--loop-cpus", str(slave_cpu), "--other-cpus", others,
             "--rt-priority", str(SPLIT_SLAVE_PRIORITY)])


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="haptic-session", description=script_description(__doc__),
                                     allow_abbrev=False)
    parser.add_argument("--duration", type=float, default=4.0, metavar="S",
                        help="run length of the loops in the simulated rig's time, s (default "
                        "4; a loaded machine takes longer in wall time, never less scenario)")
    parser.add_argument("--out", type=Path, default=Path("out/session"), metavar="DIR",
                        help="report directory (default out/session)")
    parser.add_argument("--config", metavar="FILE", help="TOML configuration for both programs")
    parser.add_argument("--scenario", default="constant-rate", help="slave scenario")
    parser.add_argument("--operator", default=DEFAULT_OPERATOR, help="simulated operator spec")
    parser.add_argument("--rig", default="sim", choices=("sim", "model"),
                        help="the master's simulated handle: sim (emulated CAN drives and "
                        "sensor, default) or model (the rig block, no bus)")
    parser.add_argument("--k", type=float, help="gain k of Ch1 (both programs)")
    parser.add_argument("--one-way-delay", dest="delay", type=float, metavar="S",
                        help="one-way delay injected in each direction, s")
    add_retired_delay_option(parser)
    parser.add_argument("--allow-unstable", action="store_true",
                        help="pass --allow-unstable to both programs")
    parser.add_argument("--governor", action="store_true",
                        help="the master's margin governor (docs/governor.md); delay profiles "
                        "come from --config ([link.<side>.injection] delay_profile)")
    parser.add_argument("--cpu-layout", choices=CPU_LAYOUTS,
                        default=LOOPS_ON_SEPARATE_CPUS.name,
                        help=f"{LOOPS_ON_SEPARATE_CPUS.help_text()} (default); "
                        f"{SESSION_UNPINNED.help_text()}")
    parser.add_argument("--master-args", default="", help="extra master arguments (one string)")
    parser.add_argument("--slave-args", default="", help="extra slave arguments (one string)")
    add_ros2_options(parser)
    return parser


def _end(process: subprocess.Popen) -> None:
    """SIGTERM, wait, SIGKILL: by this child's own PID; always reaped."""
    if process.poll() is None:
        process.send_signal(signal.SIGTERM)
        try:
            process.wait(timeout=TERM_GRACE_S)
        except subprocess.TimeoutExpired:
            process.kill()
    process.wait()


def _note_ended(processes: dict[str, subprocess.Popen], ended: list[str]) -> bool:
    """Append to ``ended`` each side whose program has exited and is not there yet (the
    master first when both are seen at once); True when any side has ended."""
    for side in ("master", "slave"):
        if side in processes and side not in ended and processes[side].poll() is not None:
            ended.append(side)
    return bool(ended)


def session_failure(statuses: dict[str, int | None], ended: Sequence[str]
                    ) -> tuple[int, list[str]]:
    """The session's exit status from its programs' (``statuses``: side -> exit status, a
    negative one a signal) and the lines saying why; (0, []) when both exited 0.
    ``ended``: the sides that exited on their own, in the order they did. The first of them
    to fail decides: its own status (3 for the analysis refusal), not the SIGTERM the session
    sent the other side afterwards. A side the session had to stop that then failed gives 1."""
    own = [side for side in ended if statuses.get(side) != 0]
    if own:
        code = statuses[own[0]]
        lines = [f"haptic-session: {side} exited with status {statuses[side]}" for side in own]
        lines += [f"haptic-session: {side} stopped by the session after the {own[0]} ended "
                  f"(status {code_})" for side, code_ in statuses.items()
                  if side not in ended and code_ != 0]
        return (code if code is not None and code > 0 else 1), lines
    stopped = {side: code for side, code in statuses.items() if code != 0}
    if not stopped:
        return 0, []
    return 1, [f"haptic-session: {side} exited with status {code} when the session stopped it"
               for side, code in stopped.items()]


def _session_key() -> Path:
    """A fresh pre-shared key for this session's two programs (common/wire/auth.py), in a private
    directory removed when the session ends: no other process can join the pair."""
    directory = tempfile.mkdtemp(prefix="haptic-session-")
    atexit.register(shutil.rmtree, directory, True)
    return write_key_file(Path(directory) / "session.key")


def _shared_program_args(args: argparse.Namespace, prefix: str) -> list[str]:
    """The options both programs get: the key prefix, the session key, the peer wait, and the
    configuration, gain, delay, stability and ROS 2 options the session was given."""
    common = ["--key-prefix", prefix, "--no-status", "--peer-wait", "30",
              "--session-key", str(_session_key())]
    if args.config:
        common += ["--config", args.config]
    if args.k is not None:
        common += ["--k", repr(args.k)]
    if args.delay is not None:
        # each side injects it on what it receives; each side's analysis counts both
        common += ["--one-way-delay", repr(args.delay), "--peer-one-way-delay", repr(args.delay)]
    if args.allow_unstable:
        common.append("--allow-unstable")
    if args.governor:
        common.append("--governor")
    return common + forwarded_ros2_args(args)


def _program_commands(args: argparse.Namespace, common: list[str], endpoint: str,
                      files: dict[str, Path], wall_bound_s: float,
                      layouts: tuple[list[str], list[str]]) -> dict[str, list[str]]:
    """Each program's command line: the slave connects to ``endpoint`` and runs at most
    ``wall_bound_s`` (s) plus a margin, the master listens and steps the duration in rig
    time; each writes its summary to its ``files`` entry; ``layouts`` are the master's and
    the slave's CPU options."""
    master_layout, slave_layout = layouts
    return {
        "slave": [sys.executable, "-m", "haptic.slave_sim.cli", *common,
                  "--duration", repr(wall_bound_s + 5.0), "--connect", endpoint,
                  "--scenario", args.scenario, "--out", str(args.out),
                  "--json-summary", str(files["slave"]), *slave_layout,
                  *shlex.split(args.slave_args)],
        "master": [sys.executable, "-m", "haptic.master.cli", *common,
                   "--rig-time", repr(args.duration), "--listen", endpoint, "--rig", args.rig,
                   "--operator", args.operator, "--out", str(args.out),
                   "--json-summary", str(files["master"]), *master_layout,
                   *shlex.split(args.master_args)],
    }


def _run_programs(commands: dict[str, list[str]],
                  deadline_after_s: float) -> tuple[dict[str, int | None], list[str]] | None:
    """Start the slave, then the master; wait until one ends or ``deadline_after_s`` (s) pass,
    then end both (each by its own PID) and reap them. Returns each side's exit status and
    the sides that ended on their own, first first; None after Ctrl-C (both ended too)."""
    processes: dict[str, subprocess.Popen] = {}
    ended: list[str] = []
    try:
        for side in ("slave", "master"):
            processes[side] = subprocess.Popen(commands[side])
        deadline = time.monotonic() + deadline_after_s
        while not _note_ended(processes, ended) and time.monotonic() < deadline:
            time.sleep(0.05)
        if ended == ["slave"]:
            # the slave died: give the master a moment, then stop it
            time.sleep(0.5)
            _note_ended(processes, ended)
        _end(processes["master"])
        _end(processes["slave"])
    except KeyboardInterrupt:
        print("haptic-session: interrupted; stopping the programs", file=sys.stderr)
        return None
    finally:
        for process in processes.values():
            _end(process)
    return {side: p.returncode for side, p in processes.items()}, ended


def run_session(args: argparse.Namespace) -> int:
    """Run both programs, then print the combined summary and write the report; the exit
    status as the module says."""
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    prefix = f"haptic/session-{uuid.uuid4().hex[:8]}"
    files = {"master": out / "master.json", "slave": out / "slave.json"}
    for path in files.values():
        path.unlink(missing_ok=True)
    # The master steps the duration in rig time; the slave's wall-time bound allows a slow
    # master, and the session stops the slave as soon as the master is done.
    wall_bound_s = SLOWDOWN_ALLOWANCE * args.duration
    master_layout, slave_layout = session_cpu_args(args.cpu_layout, usable_cpus())
    commands = _program_commands(args, _shared_program_args(args, prefix), endpoint, files,
                                 wall_bound_s, (master_layout, slave_layout))
    print(f"haptic-session: {args.scenario}, rig {args.rig}, operator {args.operator}, "
          f"{args.duration:g} s, "
          f"Zenoh on {endpoint}, key prefix {prefix}, CPU layout {args.cpu_layout}"
          + (f" (master {' '.join(master_layout)}; slave {' '.join(slave_layout)})"
             if master_layout else ""), flush=True)
    print(expected_duration_line(args.duration, kernels_cached(warp_kernel_cache_dir())),
          flush=True)
    outcome = _run_programs(commands, wall_bound_s + START_ALLOWANCE_S)
    if outcome is None:
        return 130
    status, lines = session_failure(*outcome)
    if status:
        print("\n".join(lines), file=sys.stderr)
        return status
    summaries = {}
    for side, path in files.items():
        if not path.is_file():
            print(f"haptic-session: {side} wrote no summary", file=sys.stderr)
            return 1
        summaries[side] = json.loads(path.read_text())
    gap = final_gap_m(summaries["master"], summaries["slave"])
    if gap is not None:  # a lane-law slave has no handle position to measure it against
        summaries["slave"]["final_position_gap_m"] = gap
    text = combined_summary(summaries["master"], summaries["slave"]) + inert_flag(summaries)
    print(text)
    plot = _plot(out)
    _report(out, args, text, summaries, plot)
    print(f"haptic-session: report in {out}/report.md")
    return 0


def inert_flag(summaries: dict[str, dict[str, Any]]) -> str:
    """The report's flag for a session that was inert (common/runtime/inert.py): a side whose peer
    was there but whose forces stayed off; empty when neither was."""
    lines = [f"\n  INERT SESSION: {side} forces off {summary.get('inert_time_s', 0.0):.1f} s "
             f"with the peer present ({summary.get('inert_reason')})"
             for side, summary in summaries.items() if summary.get("inert")]
    return "".join(lines)


def _us(value: Any) -> str:
    return "n/a" if value is None or not math.isfinite(value) else f"{value * 1e6:.1f} us"


def watchdog_trips_split(summary: dict[str, Any],
                         peer: dict[str, Any] | None = None) -> tuple[int, int]:
    """(trips during the run, trips at its end): a last trip with no return of the peer
    after it is the peer stopping first when it came after the peer's loop ended (both
    summaries' ``loop_start_time_s`` + ``duration_s``, one host's clock); without the peer's
    times, when it came in the last 1.5 s of this side's run. (The session stops the slave
    only after the master has exited, which may take longer than that on a slow machine.)"""
    end = summary.get("duration_s") or 0.0
    events = summary.get("events", [])
    trips = [i for i, e in enumerate(events) if e.get("kind") == "trip"]
    if not trips:
        return 0, 0
    last = trips[-1]
    returned = any(e.get("kind") == "peer_returned" for e in events[last:])
    trip_s = events[last]["time_s"]
    peer = peer or {}
    origin_s, peer_origin_s = summary.get("loop_start_time_s"), peer.get("loop_start_time_s")
    if origin_s is not None and peer_origin_s is not None and peer.get("duration_s"):
        at_end = origin_s + trip_s >= peer_origin_s + peer["duration_s"]
    else:
        at_end = trip_s >= end - 1.5
    if not returned and at_end:
        return len(trips) - 1, 1
    return len(trips), 0


#: The loop targets a session is held to (docs/programs.md): rate within 0.4 % of 1/Ts
#: (1845 Hz at Ts = 0.54 ms), overruns at most 0.1 %, period error p99 at most 50 us, no
#: watchdog trip while the peer runs.
MIN_RATE_RATIO = 0.996
MAX_OVERRUN_RATIO = 0.001
MAX_PERIOD_ERROR_P99_S = 50e-6
REAL_TIME_TARGETS = ("rate >= 99.6 % of 1/Ts, overruns <= 0.1 %, period error p99 <= 50 us, "
                     "no watchdog trip during the run")


def real_time_misses(master: dict[str, Any], slave: dict[str, Any]) -> list[str]:
    """The loop targets each side missed, one short text each (empty: real time)."""
    misses = []
    for name, s, peer in (("master", master, slave), ("slave", slave, master)):
        target_hz = 1.0 / s["period_s"] if s.get("period_s") else math.nan
        if not s["rate_hz"] >= MIN_RATE_RATIO * target_hz:
            misses.append(f"{name} rate {s['rate_hz']:.1f} Hz < {MIN_RATE_RATIO * target_hz:.1f}")
        if not s["overrun_ratio"] <= MAX_OVERRUN_RATIO:
            misses.append(f"{name} overruns {s['overrun_ratio'] * 100:.2f} % > "
                          f"{MAX_OVERRUN_RATIO * 100:g} %")
        error = s.get("period_p99_error_s")
        if error is None or not error <= MAX_PERIOD_ERROR_P99_S:
            misses.append(f"{name} period error p99 {_us(error)} > "
                          f"{MAX_PERIOD_ERROR_P99_S * 1e6:g} us")
        during, _ = watchdog_trips_split(s, peer)
        if during:
            misses.append(f"{name} watchdog tripped {during}x during the run")
    return misses


#: The share of the host's CPUs the session's processes may keep busy before a missed loop
#: target is put down to the host having too little CPU left (a loop then waits for one).
BUSY_HOST_SHARE = 0.75


def cpu_use_lines(master: dict[str, Any], slave: dict[str, Any], cpus: int) -> list[str]:
    """What the session's processes took of the host's ``cpus`` CPUs while the loops ran
    (each program's ``process_cpu_cores``, its loop thread's CPU per tick, the rig
    emulator's): one line, and a second when together they kept the CPUs more than
    :data:`BUSY_HOST_SHARE` busy. Empty when the programs did not report it."""
    parts, total = [], 0.0
    for name, s in (("master", master), ("slave", slave)):
        text = loop_cpu_text(s)
        if text is None:
            return []
        total += s["process_cpu_cores"]
        parts.append(f"{name} {text}")
    emulator = finite_figure(master, "rig_emulator_cpu_cores")
    if emulator is not None:
        total += emulator
        parts.append(f"rig emulator {emulator:.2f}")
    share = total / cpus if cpus > 0 else math.nan
    lines = [f"  CPU while the loops ran, in CPUs: {', '.join(parts)}; together {total:.2f} of "
             f"this host's {cpus} ({share * 100:.0f} %)"]
    if share > BUSY_HOST_SHARE:
        lines.append(f"    the session kept the host's CPUs over {BUSY_HOST_SHARE * 100:.0f} % "
                     f"busy: a loop that wakes finds them taken, so real time needs more CPUs "
                     f"or cheaper ticks (docs/programs.md)")
    return lines


def slowest_stage_line(master: dict[str, Any], slave: dict[str, Any],
                       misses: list[str]) -> str | None:
    """For each side that missed a loop target, the stage of its tick with the largest p99
    (from its ``stages``), against its step's p99: where a late tick's time went. The master's
    ``read`` with the emulated rig is the CAN cycle through ``haptic-rig-sim``, which the
    line says (``--rig model`` runs the loop without it). None when no side missed or no
    stage figures came."""
    parts = []
    for name, s in (("master", master), ("slave", slave)):
        stages = {stage: figures for stage, figures in (s.get("stages") or {}).items()
                  if finite_figure(figures, "p99_s") is not None}
        if not any(miss.startswith(name + " ") for miss in misses) or not stages:
            continue
        stage, figures = max(stages.items(), key=lambda item: item[1]["p99_s"])
        text = (f"{name} {stage} p99 {_us(figures.get('p99_s'))} of a step p99 "
                f"{_us(s.get('step_p99_s'))}")
        if name == "master" and stage == "read" and finite_figure(
                s, "rig_emulator_cpu_cores") is not None:
            text += (" (the CAN cycle, answered by the emulated drives of haptic-rig-sim; "
                     "--rig model runs the loop without them)")
        parts.append(text)
    if not parts:
        return None
    return "    slowest stage: " + "; ".join(parts)


def _loop_lines(master: dict[str, Any], slave: dict[str, Any], cpus: int) -> list[str]:
    """Both loops: rig time against wall time, steps, rates, period error, overruns, stage
    times, CPU use of the host's ``cpus`` CPUs, and the real-time verdict with what to do
    after a miss."""
    from haptic.common.runtime.stage_times import format_stages

    lines = []
    stepped = master.get("stepped_time_s")
    if stepped is not None and master.get("duration_s"):
        lines.append(f"  rig time {stepped:.2f} s stepped in {master['duration_s']:.2f} s of wall "
                     f"time")
    for name, s in (("master", master), ("slave", slave)):
        lines.append(
            f"  {name:6s} {s['steps']} steps  rate {s['rate_hz']:.1f} Hz  period error p99 "
            f"{_us(s['period_p99_error_s'])}  overruns {s['overruns']} "
            f"({s['overrun_ratio'] * 100:.3f} %)"
        )
    for name, s in (("master", master), ("slave", slave)):
        if s.get("stages"):
            lines.append(f"  {name:6s} step p50 {_us(s.get('step_p50_s'))}  p99 "
                         f"{_us(s.get('step_p99_s'))}; " + format_stages(s["stages"]))
    lines.extend(cpu_use_lines(master, slave, cpus))
    misses = real_time_misses(master, slave)
    lines.append("  real time: " + ("met (" + REAL_TIME_TARGETS + ")" if not misses
                                    else "MISSED: " + "; ".join(misses)))
    slowest = slowest_stage_line(master, slave, misses)
    if slowest is not None:
        lines.append(slowest)
    if misses:
        trips = watchdog_trips_split(master, slave)[0] + watchdog_trips_split(slave, master)[0]
        lines.extend(missed_guidance_lines(slave, GAP_TARGET_M, trips))
    return lines


def _link_lines(master: dict[str, Any], slave: dict[str, Any]) -> list[str]:
    """Each link direction's one-way delay (p50, p99) and loss, as its receiver measured
    them."""
    lines = []
    for name, s in (("master -> slave", slave), ("slave -> master", master)):
        loss = s.get("loss_ratio")
        loss_text = "n/a" if loss is None else f"{loss * 100:.3f} %"
        lines.append(f"  link {name}: one-way p50 {_us(s['link_one_way_delay_p50_s'])}  p99 "
                     f"{_us(s['link_one_way_delay_p99_s'])}  loss {loss_text}")
    return lines


def _cut_lines(slave: dict[str, Any]) -> list[str]:
    """The cut in the clay (forces in N, speeds in mm/s, volume in cm^3): its span, its means
    against the paper's, and its steady part; one line when the tool cut no clay."""
    cut = slave.get("cut_mean_force_N")
    if cut is None:
        return ["  the tool did not cut clay"]
    lines = [
        f"  in the clay ({slave.get('scenario', '?')}"
        f"{', on ' + slave['clay_device'] if slave.get('clay_device') else ''}): "
        f"{slave['cutting_time_s']:.2f} s "
        f"from the first to the last removal, removed "
        f"{slave.get('removed_volume_m3', 0.0) * 1e6:.2f} cm^3",
        f"    mean over the cut: tool force |ft| {cut:.2f} N, handle force "
        f"{_newtons(slave.get('cut_mean_handle_force_N'))}, speed "
        f"{slave['cut_mean_speed_m_s'] * 1e3:.1f} mm/s (paper, Fig. 9: 3.6 N at 38 mm/s)",
        f"    while removing clay: |ft| {slave['cutting_mean_force_N']:.2f} N, speed "
        f"{slave['cutting_mean_speed_m_s'] * 1e3:.1f} mm/s",
    ]
    ripple = slave.get("cutting_force_ripple_ratio")
    if ripple is not None:
        lines.append(
            f"    steady part ({slave['steady_cut_start_s']:.2f}-"
            f"{slave['steady_cut_end_s']:.2f} s): |ft| {slave['steady_cut_force_N']:.2f} N, "
            f"speed {slave['steady_cut_speed_m_s'] * 1e3:.1f} mm/s, force ripple "
            f"{ripple * 100:.1f} % (std/mean), velocity reversals "
            f"{slave['cutting_velocity_reversals']}"
        )
    return lines


def _newtons(value: float | None) -> str:
    """A force in N with two decimals, or ``n/a`` where the run did not measure it (the
    wave law's messages carry no handle force)."""
    return "n/a" if value is None else f"{value:.2f} N"


def final_gap_m(master: dict[str, Any], slave: dict[str, Any]) -> list[float] | None:
    """The position gap at the end (x, y), m: the slave's own (paper, tdpa: against the
    handle position it received), else, in a lane-law mode, the slave's final tool position
    less the master's final handle position (the laws scale no positions); None when
    neither is there."""
    gap = slave.get("final_position_gap_m")
    if gap is not None:
        return list(gap)
    tool, handle = slave.get("final_tool_position_m"), master.get("final_handle_position_m")
    if tool is None or handle is None:
        return None
    return [float(tool[0]) - float(handle[0]), float(tool[1]) - float(handle[1])]


def _ending_lines(master: dict[str, Any], slave: dict[str, Any]) -> list[str]:
    """How the session ended: the position gap (mm) against its target, the work area, the
    watchdog trips during the run and at its end, and the stability analysis."""
    lines = []
    gap = slave.get("final_position_gap_m")
    if gap is not None:
        lines.append(f"  position gap at the end |yt - Ah1 yh|: x {abs(gap[0]) * 1e3:.2f} mm, "
                     f"y {abs(gap[1]) * 1e3:.2f} mm (target <= {GAP_TARGET_M * 1e3:g} mm)")
    if master.get("work_area"):
        lines.append(f"  work area: {master['work_area']}")
    m_during, m_end = watchdog_trips_split(master, slave)
    s_during, s_end = watchdog_trips_split(slave, master)
    lines.append(
        f"  watchdog trips during the run: master {m_during}, slave {s_during} "
        f"(at the end, a side seeing its peer stop first: master {m_end}, slave {s_end})"
    )
    analysis = master.get("analysis") or {}
    if analysis:
        margin = analysis.get("delay_margin_s")
        margin_text = ("none (stable for every delay)" if margin is None
                       else f"{margin * 1e3:.2f} ms")
        lines.append(f"  analysis: k = {analysis['k']:g}, round trip "
                     f"{analysis['round_trip_delay_s'] * 1e3:.2f} ms, "
                     f"{'stable' if analysis['stable'] else 'UNSTABLE'}, delay margin "
                     f"{margin_text}")
    return lines


def combined_summary(master: dict[str, Any], slave: dict[str, Any],
                     cpus: int | None = None) -> str:
    """The session's lines: both loops, what they took of the host's CPUs (``cpus``, default
    this process's usable CPUs), both link directions, forces, the cut, the watchdog."""
    lines = ["session summary" + (f" ([control] mode = {master['control']})"
                                  if master.get("control") else "")]
    lines += _loop_lines(master, slave, usable_cpu_count() if cpus is None else cpus)
    lines += _link_lines(master, slave)
    lines.append(f"  max |force|: reflected to the operator {master['max_abs_force_N']:.2f} N,"
                 f" tool on the clay {slave['max_abs_force_N']:.2f} N")
    lines += _cut_lines(slave)
    lines += _ending_lines(master, slave)
    return "\n".join(lines)


def _plot(out: Path) -> Path | None:
    """Forces against time, tool velocity against position, from the two traces."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        import numpy as np

        slave = np.load(out / "slave_trace.npz")
        master = np.load(out / "master_trace.npz")
    except (OSError, ImportError) as error:
        print(f"haptic-session: no plot ({error})", file=sys.stderr)
        return None
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 7))
    ax1.plot(master["time_s"], master["handle_force_x_N"], label="handle force fh_x (master)")
    ax1.plot(slave["time_s"], slave["tool_force_x_N"], label="tool force ft_x (slave)",
             alpha=0.8)
    ax1.axhline(3.6, color="k", lw=0.6, ls="--", label="3.6 N (paper)")
    ax1.set_xlabel("time since each loop's start, s")
    ax1.set_ylabel("force, N")
    ax1.legend(loc="upper left", fontsize=8)
    ax1.grid(alpha=0.3)
    ax2.plot(slave["tool_position_x_m"] * 1e3, slave["tool_velocity_x_m_s"] * 1e3, lw=0.7)
    ax2.axhline(38.0, color="k", lw=0.6, ls="--", label="38 mm/s (paper)")
    ax2.set_xlabel("tool position x, mm")
    ax2.set_ylabel("tool velocity x, mm/s")
    ax2.legend(loc="upper left", fontsize=8)
    ax2.grid(alpha=0.3)
    fig.tight_layout()
    path = out / "session.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _report(out: Path, args: argparse.Namespace, text: str, summaries: dict[str, Any],
            plot: Path | None) -> None:
    parts = [
        "# haptic-session report", "",
        f"Scenario `{args.scenario}`, operator `{args.operator}`, {args.duration:g} s, both "
        "programs on loopback over Zenoh.", "",
        "```", text, "```", "",
    ]
    for name in ("clay.png", "session.png"):
        if (out / name).is_file():
            parts += [f"![{name}]({name})", ""]
    for side in ("master", "slave"):
        parts += [f"## {side} summary (`{side}.json`)", "", "```json",
                  json.dumps(summaries[side], indent=2, sort_keys=True), "```", ""]
    (out / "report.md").write_text("\n".join(parts))


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if not (math.isfinite(args.duration) and args.duration > 0.0):
        print(f"config error: --duration: must be > 0 s (got {args.duration:g})",
              file=sys.stderr)
        return 2
    if args.config:  # checked here once, before any program starts: one line, exit status 2
        from haptic.common.config import ConfigError, load_config
        from haptic.common.model.teleop import model_from_config

        try:
            model_from_config(load_config(args.config))
        except ConfigError as error:
            print(f"config error: {error}", file=sys.stderr)
            return 2
    return run_session(args)


if __name__ == "__main__":
    sys.exit(main())
