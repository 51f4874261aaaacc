"""Loop benchmark: the real-time loop over our Zenoh link, next to a raw Zenoh ping-pong.

Runs, in one invocation on loopback:

1. the floor: a raw zenoh-python ping-pong between this process and a child (express,
   real-time priority, ``RingChannel``), one-way delay = round trip / 2 on
   :func:`time.perf_counter_ns`, 10000 round trips before and 10000 after the loop, pooled
   (the machine's noise drifts);
2. the loop: two processes, each a :class:`~haptic.common.runtime.runner.RealTimeRunner` at Ts
   with a :class:`~haptic.common.wire.link.Link`, exchanging HandleState and ToolState every tick.

By default the two loop processes are the real programs: ``haptic-master`` on the ``model``
handle backend (the rig block stepped in ``read()``, the regulating operator holding 3.6 N;
``--rig sim`` puts the emulated CAN drives and sensor with their thread in the loop) and
``haptic-slave`` cutting the constant-rate clay, each started as ``python -m`` of its module.
``--echo`` runs this file's ``--role master`` / ``--role slave`` echo nodes instead (a
watchdog, a poll, a send per tick; no control law, no hardware): the link and runner alone.
:func:`run_pair` takes any two commands that accept the shared run options (``--duration``,
``--json-summary``, ``--listen``/``--connect``, ``--key-prefix``, ``--no-status``);
``--master-cmd`` and ``--slave-cmd`` give others. Each side's figures include what its process
took of the machine, from its summary: ``process_cpu_cores`` and the loop thread's CPU per
tick, ``loop_thread_cpu_per_step_s``.

The stages (``stages.<name>.p50_s``/``p99_s``) are each stage's whole time per tick. The
slave's node stage runs one node step per master sample (slave_sim/pacing.py: none while the
next has not come, several after a gap), so its p99 holds the catch-up ticks; the slave's
figures add ``node_per_step`` (the node part's time divided by the tick's node steps, over the
ticks with at least one) and ``node_steps_per_tick`` (the step count -> the ticks with it and
their node part's p50/p99), both timed inside ``SlaveTick.step_lane``.

CPU layout (``--cpu-layout``, :func:`cpu_layout_args`): ``partitioned`` by default, as on a rig
PC: both loops in SCHED_FIFO 40 on the last CPU (the slave's phase lock makes them take turns),
a 20 us spin, and every other thread (Zenoh's, the display's) on the other CPUs. ``free``
(the default for ``--echo`` and custom commands, which have no phase lock): the loops in
SCHED_FIFO anywhere, the other threads wherever the kernel puts them. The raw
ping-pong is never pinned: it is Zenoh as it comes.

Usage::

    python bench/loop_bench.py --duration 10            # a table
    python bench/loop_bench.py --duration 10 --json     # one JSON object
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shlex
import signal
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path
from typing import Any

import numpy as np
import zenoh

from haptic.common.config import exit_on_config_error, load_config
from haptic.common.runtime.cli_options import add_run_options, run_options_from_args
from haptic.common.runtime.cpu_layout import (
    LOOP_BENCH_LAYOUTS,
    LOOPS_FIFO_ANYWHERE,
    LOOPS_SHARING_ONE_CPU,
    layout_names,
)
from haptic.common.runtime.realtime import cpu_latency_request
from haptic.common.runtime.runner import RealTimeRunner, StopSignals
from haptic.common.runtime.runner_config import place_other_threads, prioritise_zenoh_threads
from haptic.common.runtime.stage_times import in_tick_order
from haptic.common.runtime.summary import (
    format_summary,
    loop_cpu_text,
    make_summary,
    write_json_summary,
)
from haptic.common.runtime.watchdog import PeerWatchdog
from haptic.common.wire.link import Link
from haptic.common.wire.messages import Flags
from haptic.common.wire.ports import free_port

PEER_WAIT_S = 10.0


def _peer_config(listen: str | None = None, connect: str | None = None) -> zenoh.Config:
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("scouting/multicast/enabled", "false")
    if listen:
        conf.insert_json5("listen/endpoints", json.dumps([listen]))
    if connect:
        conf.insert_json5("connect/endpoints", json.dumps([connect]))
    return conf


# -- raw zenoh ping-pong -------------------------------------------------------------------

#: Round trips of the paced ping-pong before and after the loop (one per Ts: about 1 s each).
PACED_ROUND_TRIPS = 2000


def pong(endpoint: str, prefix: str) -> None:
    """Echo every ``<prefix>/ping`` sample on ``<prefix>/pong`` until the ping says stop."""
    with zenoh.open(_peer_config(connect=endpoint)) as session:
        sub = session.declare_subscriber(f"{prefix}/ping", zenoh.handlers.RingChannel(16))
        pub = session.declare_publisher(
            f"{prefix}/pong", express=True, congestion_control=zenoh.CongestionControl.DROP,
            priority=zenoh.Priority.REAL_TIME,
        )
        token = session.liveliness().declare_token(f"{prefix}/alive/pong")
        while True:
            sample = sub.recv()
            payload = sample.payload.to_bytes()
            if payload == b"stop":
                break
            pub.put(payload)
        token.undeclare()


def raw_ping_pong(round_trips: int = 10000, warmup: int = 200,
                  period_s: float = 0.0) -> np.ndarray:
    """One-way delays (s, round trip / 2) of a raw zenoh-python ping-pong with a child
    process: back to back by default, or one ping every ``period_s`` (s) as the loop sends."""
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    prefix = f"bench/{uuid.uuid4().hex[:8]}"
    rtts = np.empty(round_trips)
    with zenoh.open(_peer_config(listen=endpoint)) as session:
        sub = session.declare_subscriber(f"{prefix}/pong", zenoh.handlers.RingChannel(1))
        pub = session.declare_publisher(
            f"{prefix}/ping", express=True, congestion_control=zenoh.CongestionControl.DROP,
            priority=zenoh.Priority.REAL_TIME,
        )
        alive = session.liveliness().declare_subscriber(
            f"{prefix}/alive/pong", zenoh.handlers.FifoChannel(4), history=True
        )
        child = subprocess.Popen(
            [sys.executable, __file__, "--role", "pong", "--endpoint", endpoint,
             "--prefix", prefix],
        )
        try:
            deadline = time.monotonic() + PEER_WAIT_S
            while alive.try_recv() is None:
                if time.monotonic() > deadline or child.poll() is not None:
                    raise RuntimeError("the pong process did not come up")
                time.sleep(0.005)
            i = -warmup
            next_ping = time.perf_counter()
            while i < round_trips:
                if period_s > 0.0:
                    next_ping += period_s
                    wait = next_ping - time.perf_counter()
                    if wait > 0.0:
                        time.sleep(wait)
                payload = i.to_bytes(8, "little", signed=True)
                t0 = time.perf_counter_ns()
                pub.put(payload)
                reply_deadline = t0 + 1_000_000_000
                while True:
                    sample = sub.try_recv()
                    if sample is not None and sample.payload.to_bytes() == payload:
                        break
                    if time.perf_counter_ns() > reply_deadline:
                        sample = None
                        break
                t1 = time.perf_counter_ns()
                if sample is not None and i >= 0:
                    rtts[i] = (t1 - t0) * 1e-9
                i += 1 if sample is not None else 0
            pub.put(b"stop")
            child.wait(timeout=5)
        finally:
            if child.poll() is None:
                child.kill()
            child.wait()
    return rtts / 2.0


def summarise_one_way(one_way_s: np.ndarray) -> dict[str, float]:
    return {
        "one_way_p50_s": float(np.percentile(one_way_s, 50)),
        "one_way_p99_s": float(np.percentile(one_way_s, 99)),
        "round_trips": int(one_way_s.size),
    }


# -- the echo nodes --------------------------------------------------------------------------


def echo_node(side: str, argv: list[str]) -> int:
    """A minimal node on the real runner and link: poll, watchdog, send. Returns the exit
    status."""
    parser = argparse.ArgumentParser(allow_abbrev=False, prog=f"loop_bench {side}")
    add_run_options(parser)
    args = parser.parse_args(argv)
    with exit_on_config_error():
        options = run_options_from_args(args, side)
    config = options.config
    period_s = config["model"]["sample_period_s"]
    watchdog = PeerWatchdog(options.link.max_message_age_s, options.link.resync_messages)
    max_force = 0.0
    zenoh_threads = place_other_threads(options.runner)  # before Zenoh's threads start
    with StopSignals() as signals, Link(options.link) as link:
        if not link.wait_for_peer(PEER_WAIT_S, lambda: signals.requested):
            if signals.requested:
                return 0
            print(f"{side}: no peer after {PEER_WAIT_S} s", file=sys.stderr)
            return 1
        zenoh_threads.update(prioritise_zenoh_threads(options.runner))
        state: dict[str, Any] = {"force": (0.0, 0.0), "position": (0.0, 0.0)}

        def step(tick: int, now_ns: int) -> None:
            nonlocal max_force
            message = link.poll()
            fresh = message is not None
            watchdog.update(now_ns * 1e-9, fresh, link.silence_s(), True, link.peer_alive)
            flags = Flags.FORCES_ENABLED if watchdog.forces_enabled else Flags.SAFE_STATE
            if side == "master":
                phase = 2.0 * math.pi * 1.0 * tick * period_s
                force = (3.0 * math.sin(phase), 3.0 * math.cos(phase))
                link.send_handle(force, (0.01 * force[0], 0.01 * force[1]), flags)
                if fresh and watchdog.forces_enabled:
                    max_force = max(max_force, abs(message.tool_force_N[0]))
            else:
                if fresh:
                    state["force"] = message.handle_force_N
                    state["position"] = message.handle_position_m
                link.send_tool(state["force"], state["position"], (0.0, 0.0), 0.0, 0.0, flags)

        def status() -> str:
            s = link.stats()
            return (
                f"delay p50 {s.one_way_delay_p50_s * 1e6:.0f} us  loss "
                f"{s.loss_ratio * 100:.2f} %"
            )

        runner = RealTimeRunner(
            period_s, step, duration_s=options.duration_s, status=status,
            spin_s=options.runner.spin_s, realtime=options.runner.realtime,
            stop_signals=signals, freeze_heap=True,
            show_status=options.show_status,
        )
        run = runner.run()
        summary = make_summary(
            run.as_summary(),
            link.summary(),
            max_abs_force_N=max_force,
            watchdog_trips=watchdog.trips,
            events=[e.as_dict() for e in watchdog.events],
            side=side,
            **zenoh_threads,
        )
    if options.json_summary is not None:
        write_json_summary(options.json_summary, summary)
    print(f"{side}: {format_summary(summary)}", file=sys.stderr)
    return 0


# -- the pair --------------------------------------------------------------------------------


PROGRAM_COMMANDS = {
    "master": [sys.executable, "-m", "haptic.master.cli", "--operator",
               "regulate:fx=3.6,onset=0.2,max=5", "--peer-wait", "30"],
    "slave": [sys.executable, "-m", "haptic.slave_sim.cli", "--scenario", "constant-rate",
              "--peer-wait", "30"],
}


def default_command(side: str, echo: bool = False, rig: str = "model") -> list[str]:
    """The real program of ``side`` (``haptic-master`` on the handle hardware ``rig``,
    ``haptic-slave``), or this file's echo node with ``echo``."""
    if echo:
        return [sys.executable, os.path.abspath(__file__), "--role", side]
    command = list(PROGRAM_COMMANDS[side])
    if side == "master":
        command += ["--rig", rig]
    return command


#: How the benchmark places the two programs' threads on the CPUs (not haptic-session's
#: layouts: common/runtime/cpu_layout.py).
CPU_LAYOUTS = layout_names(LOOP_BENCH_LAYOUTS)


def cpu_layout_args(layout: str, cpus: list[int] | None = None) -> list[str]:
    """The run options of a CPU layout (docs/link.md section 9) on the CPUs this process may
    use (``cpus``; default: its affinity).

    ``partitioned`` (the default for the programs with 2 CPUs or more, as on a rig PC): both
    loops on the last CPU in SCHED_FIFO, kept apart in time by the slave's phase lock (its
    margin: :func:`slave_layout_args`), with a 20 us spin; every other thread (Zenoh's, the
    display's) on the other CPUs. ``free``: the loops in SCHED_FIFO on any CPU with the
    default spin, Zenoh's threads in SCHED_FIFO below them (:data:`FREE_ZENOH_PRIORITY`),
    everything else where the kernel puts it.
    """
    if layout not in CPU_LAYOUTS:
        raise ValueError(f"cpu layout must be one of {', '.join(CPU_LAYOUTS)} (got {layout!r})")
    common = ["--rt-priority", "40"]
    if cpus is None:
        cpus = (sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity")
                else list(range(os.cpu_count() or 1)))
    if layout == LOOPS_FIFO_ANYWHERE.name:
        return [*common, "--zenoh-priority", str(FREE_ZENOH_PRIORITY)]
    if len(cpus) < 2:
        return common
    others = ",".join(str(cpu) for cpu in cpus[:-1])
    return [*common, "--loop-cpus", str(cpus[-1]), "--other-cpus", others, "--spin-s", "0.00002"]


#: The free layout's SCHED_FIFO priority of Zenoh's threads, below the loops' 40. Two FIFO loops
#: that may run on any CPU leave Zenoh's normal threads only their gaps: on 2 CPUs the master's
#: samples then reached the slave in bunches, a slave tick waiting for a sample that came
#: late; Zenoh's threads in SCHED_FIFO take their turn (runner.zenoh_thread_priority;
#: docs/link.md section 9, figures in docs/measurements/loop_bench.md).
FREE_ZENOH_PRIORITY = 30

#: The slave program's phase margin in the partitioned layout, s: its spin starts this long
#: after the master's message arrives (the lag is the 20 us spin plus this). Both loops share
#: one CPU there, so the slave's tick must come after the master's work behind its send (its
#: telemetry, p99 about 30 us): with the shipped 30 us a master still running at the slave's
#: deadline widened the slave's period error (docs/measurements/loop_bench.md). It costs the
#: slave's age at use 30 us.
PARTITIONED_SLAVE_MARGIN_S = 0.00006


def slave_layout_args(layout: str, cpus: list[int] | None = None) -> list[str]:
    """The slave program's own options of a CPU layout (its phase lock's margin where both
    loops share a CPU); nothing for the free layout or a single CPU."""
    if "--loop-cpus" not in cpu_layout_args(layout, cpus):
        return []
    return ["--phase-margin", repr(PARTITIONED_SLAVE_MARGIN_S)]


def run_pair(
    master_cmd: list[str],
    slave_cmd: list[str],
    duration_s: float,
    extra_args: list[str] | None = None,
    timeout_s: float | None = None,
    cpu_layout: str = LOOPS_SHARING_ONE_CPU.name,
) -> tuple[dict[str, Any], dict[str, Any]]:
    """Run the master and slave commands on loopback for ``duration_s`` and return their JSON
    summaries. Both get ``--duration``, ``--json-summary``, ``--no-status``, a fresh key
    prefix and port (master ``--listen``, slave ``--connect``), the options of ``cpu_layout``
    (:func:`cpu_layout_args`) and ``extra_args`` (after them, so they can override)."""
    port = free_port()
    prefix = f"bench/{uuid.uuid4().hex[:8]}"
    endpoint = f"tcp/127.0.0.1:{port}"
    common = ["--duration", str(duration_s), "--key-prefix", prefix, "--no-status",
              *cpu_layout_args(cpu_layout), *(extra_args or [])]
    timeout = timeout_s if timeout_s is not None else duration_s + 60.0
    with tempfile.TemporaryDirectory(prefix="loop_bench_") as tmp:
        files = {side: Path(tmp) / f"{side}.json" for side in ("master", "slave")}
        commands = {
            "master": [*master_cmd, *common, "--listen", endpoint,
                       "--json-summary", str(files["master"])],
            "slave": [*slave_cmd, *common, "--connect", endpoint,
                      "--json-summary", str(files["slave"])],
        }
        processes = {side: subprocess.Popen(cmd) for side, cmd in commands.items()}
        try:
            end = time.monotonic() + timeout
            for process in processes.values():
                process.wait(timeout=max(1.0, end - time.monotonic()))
        finally:
            for process in processes.values():
                if process.poll() is None:
                    process.send_signal(signal.SIGTERM)
                    try:
                        process.wait(timeout=3)
                    except subprocess.TimeoutExpired:
                        process.kill()
                process.wait()
        for side, process in processes.items():
            if process.returncode != 0:
                raise RuntimeError(f"{side} exited with status {process.returncode}")
        return tuple(json.loads(files[s].read_text()) for s in ("master", "slave"))  # type: ignore[return-value]


def _side_figures(summary: dict[str, Any], ts_s: float) -> dict[str, Any]:
    return {
        "rate_hz": summary["rate_hz"],
        "target_rate_hz": 1.0 / ts_s,
        "period_p50_error_s": summary.get("period_p50_error_s"),
        "period_p99_error_s": summary["period_p99_error_s"],
        "period_max_error_s": summary.get("period_max_error_s"),
        "overruns": summary["overruns"],
        "overrun_ratio": summary["overrun_ratio"],
        "steps": summary["steps"],
        "stalls": summary.get("stalls"),
        "step_p50_s": summary.get("step_p50_s"),
        "step_p99_s": summary.get("step_p99_s"),
        "stages": {name: {"p50_s": f["p50_s"], "p99_s": f["p99_s"]}
                   for name, f in in_tick_order(summary.get("stages") or {})},
        "watchdog_trips": summary.get("watchdog_trips"),
        "scheduling": summary.get("scheduling"),
        "process_cpu_cores": summary.get("process_cpu_cores"),
        "loop_thread_cpu_per_step_s": summary.get("loop_thread_cpu_per_step_s"),
        # the slave's node steps per tick (slave_sim/pacing.py): caught-up steps make a
        # tick's node stage two or more steps long
        "pacing": {key.removeprefix("pacing_"): value for key, value in summary.items()
                   if key.startswith("pacing_")} or None,
        **_node_step_figures(summary.get("node_times")),
    }


def _node_step_figures(node_times: dict[str, Any] | None) -> dict[str, Any]:
    """What the slave's node stage p99 holds (slave_sim/pacing.py: one node step per master
    sample, 0 to several a tick): ``node_per_step``, the node part's time divided by the
    tick's node steps over the ticks with at least one step (p50/p99/max/mean, s; timed inside
    ``SlaveTick.step_lane``, from the supervise | node boundary to the node part's end, so
    it leaves out the stage's last few instructions), and ``node_steps_per_tick``, the step
    count -> the ticks with it and their node part's p50/p99, s. Empty for a side without
    them (the master, the echo nodes)."""
    if not node_times:
        return {}
    return {"node_per_step": node_times["per_step"],
            "node_steps_per_tick": node_times["by_steps"]}


def _phase_lock(slave: dict[str, Any]) -> dict[str, Any] | None:
    """How closely the slave's phase lock held its lag: the master's messages used this long
    after they arrived (age at use minus one-way delay, p50), s."""
    if not slave.get("phase_lock_enabled"):
        return None
    age, delay = slave.get("link_age_at_use_p50_s"), slave.get("link_one_way_delay_p50_s")
    used_after = age - delay if age is not None and delay is not None else None
    return {"lag_s": slave.get("phase_lock_lag_s"), "used_after_arrival_p50_s": used_after,
            "locked_ratio": slave.get("phase_lock_locked_ratio")}


def _direction(summary: dict[str, Any]) -> dict[str, Any]:
    return {
        "one_way_p50_s": summary["link_one_way_delay_p50_s"],
        "one_way_p99_s": summary["link_one_way_delay_p99_s"],
        "loss_ratio": summary["loss_ratio"],
        "age_at_use_p50_s": summary.get("link_age_at_use_p50_s"),
        "network_loss_ratio": summary.get("link_network_loss_ratio"),
        "dropped": {k: v for k, v in summary.get("link_dropped", {}).items() if v},
    }


def _worst(a: float | None, b: float | None) -> float | None:
    values = [v for v in (a, b) if v is not None and math.isfinite(v)]
    return max(values) if values else None


def benchmark(
    duration_s: float,
    master_cmd: list[str] | None = None,
    slave_cmd: list[str] | None = None,
    extra_args: list[str] | None = None,
    ts_s: float = 0.00054,
    echo: bool = False,
    rig: str = "model",
    cpu_layout: str = LOOPS_SHARING_ONE_CPU.name,
    cpu_latency_limit_us: int | None = None,
) -> dict[str, Any]:
    """The whole benchmark; returns the result dict (what ``--json`` prints: the link's and the
    raw ping-pong's figures, with per-direction details). The raw ping-pong runs under the CPU
    latency request the programs hold (``cpu_latency_limit_us``, us; None: the configured
    default), so that the ratio compares the link with Zenoh on the same machine state."""
    if cpu_latency_limit_us is None:
        cpu_latency_limit_us = int(load_config()["runner"]["cpu_latency_limit_us"])
    with cpu_latency_request(cpu_latency_limit_us) as (held_us, latency_warning):
        before = raw_ping_pong()
        paced_before = raw_ping_pong(PACED_ROUND_TRIPS, 50, period_s=ts_s)
        # the phase margin is the slave program's own option (not the echo node's)
        slave_args = [] if slave_cmd or echo else slave_layout_args(cpu_layout)
        master, slave = run_pair(
            master_cmd or default_command("master", echo, rig),
            [*(slave_cmd or default_command("slave", echo)), *slave_args], duration_s,
            extra_args, cpu_layout=cpu_layout,
        )
        raw = summarise_one_way(np.concatenate([before, raw_ping_pong()]))
        paced = summarise_one_way(np.concatenate(
            [paced_before, raw_ping_pong(PACED_ROUND_TRIPS, 50, period_s=ts_s)]))
    to_slave = _direction(slave)   # the slave receives master -> slave
    to_master = _direction(master)
    link = {
        "one_way_p50_s": _worst(to_slave["one_way_p50_s"], to_master["one_way_p50_s"]),
        "one_way_p99_s": _worst(to_slave["one_way_p99_s"], to_master["one_way_p99_s"]),
        "loss_ratio": _worst(to_slave["loss_ratio"], to_master["loss_ratio"]),
        "master_to_slave": to_slave,
        "slave_to_master": to_master,
    }
    ratio = (
        link["one_way_p50_s"] / raw["one_way_p50_s"]
        if link["one_way_p50_s"] is not None and raw["one_way_p50_s"] > 0
        else None
    )
    return {
        "duration_s": duration_s,
        "cpu_layout": cpu_layout,
        "run_options": cpu_layout_args(cpu_layout) + list(extra_args or []),
        "slave_run_options": slave_args,
        "nodes": "echo" if echo and not (master_cmd or slave_cmd) else (
            "custom" if master_cmd or slave_cmd else f"programs, rig {rig}"),
        "period_s": ts_s,
        "master": _side_figures(master, ts_s),
        "slave": _side_figures(slave, ts_s),
        "phase_lock": _phase_lock(slave),
        "link": link,
        "raw_zenoh": raw,
        "link_to_raw_p50_ratio": ratio,
        # context, not the target: the same ping-pong one ping per Ts, as the loop sends
        "raw_zenoh_paced": {**paced, "period_s": ts_s},
        "link_to_raw_paced_p50_ratio": (
            link["one_way_p50_s"] / paced["one_way_p50_s"]
            if link["one_way_p50_s"] is not None and paced["one_way_p50_s"] > 0 else None),
        # the CPU latency request held through the run (us; None: none or refused)
        "cpu_latency_limit_us": held_us,
        "cpu_latency_warning": latency_warning,
    }


def _us(value: float | None) -> str:
    return "n/a" if value is None else f"{value * 1e6:8.1f} us"


def print_node_steps(figures: dict[str, Any]) -> None:
    """The slave's node part per node step and its ticks by node steps (none: nothing)."""
    per_step = figures.get("node_per_step")
    if not per_step or not per_step.get("ticks"):
        return
    print(f"         node part per node step (ticks with >= 1 step): p50 "
          f"{per_step['p50_s'] * 1e6:.1f} p99 {per_step['p99_s'] * 1e6:.1f} us")
    print("         ticks by node steps (ticks, node part p50/p99 us): " + "  ".join(
        f"{steps}: {entry['ticks']}" + (f" ({entry['p50_s'] * 1e6:.1f}/"
                                        f"{entry['p99_s'] * 1e6:.1f})" if "p50_s" in entry
                                        else "")
        for steps, entry in figures.get("node_steps_per_tick", {}).items()))


def print_table(result: dict[str, Any]) -> None:
    print(f"loop benchmark, {result['duration_s']:g} s on loopback, nodes: "
          f"{result.get('nodes', '?')}, CPU layout {result.get('cpu_layout', '?')} "
          f"({' '.join(result.get('run_options', []))}"
          + (f"; slave {' '.join(result['slave_run_options'])}"
             if result.get("slave_run_options") else "") + ")")
    held = result.get("cpu_latency_limit_us")
    print(f"  CPU latency request: {'none' if held is None else f'{held} us'}"
          + (f" ({result['cpu_latency_warning']})" if result.get("cpu_latency_warning") else ""))
    for side in ("master", "slave"):
        f = result[side]
        print(
            f"  {side:6s} rate {f['rate_hz']:8.1f} Hz (target {f['target_rate_hz']:.1f})  "
            f"period error p50 {_us(f['period_p50_error_s'])} p99 {_us(f['period_p99_error_s'])}"
            f" max {_us(f['period_max_error_s'])}  overruns {f['overruns']} "
            f"({f['overrun_ratio'] * 100:.3f} %)  step p50 {_us(f.get('step_p50_s'))} p99 "
            f"{_us(f.get('step_p99_s'))}"
        )
        cpu = loop_cpu_text(f)
        if cpu is not None:
            print(f"         CPU in CPUs: {cpu}")
        if f.get("stages"):
            print("         stages p50/p99: " + "  ".join(
                f"{name} {g['p50_s'] * 1e6:.1f}/{g['p99_s'] * 1e6:.1f}"
                for name, g in f["stages"].items()) + " us")
        pacing = f.get("pacing")
        if pacing and pacing.get("follow_master_samples"):
            print(f"         node steps: {pacing['waited_ticks']} ticks waited, "
                  f"{pacing['caught_up_steps']} caught up, most in one tick "
                  f"{pacing['max_tick_steps']}, largest backlog "
                  f"{pacing['max_backlog_samples']}")
        print_node_steps(f)
    lock = result.get("phase_lock")
    if lock and lock.get("used_after_arrival_p50_s") is not None:
        print(f"  slave phase lock: the master's messages used "
              f"{lock['used_after_arrival_p50_s'] * 1e6:.1f} us after arrival (p50; target lag "
              f"{lock['lag_s'] * 1e6:.1f} us), locked {lock['locked_ratio'] * 100:.1f} % of "
              "updates")
    link = result["link"]
    for name in ("master_to_slave", "slave_to_master"):
        d = link[name]
        print(
            f"  link {name:15s} one-way p50 {_us(d['one_way_p50_s'])} p99 "
            f"{_us(d['one_way_p99_s'])}  loss {d['loss_ratio'] * 100:.3f} %  "
            f"(age at use p50 {_us(d['age_at_use_p50_s'])})"
            + (f"  dropped {d['dropped']}" if d["dropped"] else "")
        )
    raw = result["raw_zenoh"]
    print(f"  raw zenoh ping-pong one-way p50 {_us(raw['one_way_p50_s'])} p99 "
          f"{_us(raw['one_way_p99_s'])}")
    ratio = result["link_to_raw_p50_ratio"]
    print(f"  link / raw one-way p50: {ratio:.2f}" if ratio is not None else "  ratio: n/a")
    paced = result.get("raw_zenoh_paced")
    if paced is not None:
        paced_ratio = result.get("link_to_raw_paced_p50_ratio")
        print(f"  (context) raw ping-pong paced at Ts one-way p50 {_us(paced['one_way_p50_s'])} "
              f"p99 {_us(paced['one_way_p99_s'])}; link / paced p50: "
              + (f"{paced_ratio:.2f}" if paced_ratio is not None else "n/a"))


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    zenoh.init_log_from_env_or("error")
    if len(argv) >= 2 and argv[0] == "--role":
        role, rest = argv[1], argv[2:]
        if role == "pong":
            parser = argparse.ArgumentParser(allow_abbrev=False, prog="loop_bench pong")
            parser.add_argument("--endpoint", required=True)
            parser.add_argument("--prefix", required=True)
            args = parser.parse_args(rest)
            pong(args.endpoint, args.prefix)
            return 0
        if role in ("master", "slave"):
            return echo_node(role, rest)
        print(f"unknown role {role}", file=sys.stderr)
        return 2
    parser = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=10.0, help="loop run length, s")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    parser.add_argument("--master-cmd", help="master command (default: haptic-master)")
    parser.add_argument("--slave-cmd", help="slave command (default: haptic-slave)")
    parser.add_argument("--rig", default="model",
                        help="the master's handle hardware: sim (emulated CAN drives) "
                        "or model (the rig block, no bus; default)")
    parser.add_argument("--echo", action="store_true",
                        help="run the echo nodes (link and runner only) instead of the programs")
    parser.add_argument("--cpu-layout", choices=CPU_LAYOUTS,
                        help="partitioned (default for the programs at the configured period): "
                        "both loops on the last CPU, the other threads on the rest; free "
                        "(default for --echo, custom commands, which have no phase lock, and "
                        "a --period under the configured one, where both ticks do not fit "
                        "one CPU): anywhere")
    parser.add_argument(
        "--extra", default="", help="extra arguments for both commands (one shell string)"
    )
    parser.add_argument("--cpu-latency-us", type=int, default=None, metavar="US",
                        help="the CPU latency request held through the run and by both "
                        "programs, us (-1: none; default: the configured "
                        "runner.cpu_latency_limit_us)")
    parser.add_argument("--period", type=float, default=None, metavar="S",
                        help="sample period Ts of both programs, s (default: the configured "
                        "0.54 ms); the compensators are synthesised at this period")
    args = parser.parse_args(argv)
    extra = shlex.split(args.extra)
    if args.cpu_latency_us is not None:
        if args.cpu_latency_us < -1:
            print("config error: --cpu-latency-us: must be -1 (none) or >= 0 us (got "
                  f"{args.cpu_latency_us})", file=sys.stderr)
            return 2
        extra += ["--cpu-latency-us", str(args.cpu_latency_us)]
    ts_s = 0.00054
    with tempfile.TemporaryDirectory() as folder:
        if args.period is not None:
            if not 0.0 < args.period <= 0.01:
                print(f"config error: --period: must be in (0, 0.01] s (got {args.period:g})",
                      file=sys.stderr)
                return 2
            ts_s = args.period
            extra += ["--config", str(period_config(Path(folder), ts_s))]
        result = _run(args, extra, ts_s)
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        print_table(result)
    return 0


#: The spin before each tick as a share of the period, where ``--period`` asks for a period
#: shorter than the configured one: the shipped 0.1 ms (a sleep on these VMs wakes 16-36 us
#: late, p50) is 40 % of a 0.25 ms period, and two loops spinning that long leave Zenoh's
#: threads too little of 2 CPUs.
SHORT_PERIOD_SPIN_SHARE = 0.1


def period_config(folder: Path, period_s: float) -> Path:
    """A configuration file that sets the sample period, s, and for a period under the
    configured one a spin of :data:`SHORT_PERIOD_SPIN_SHARE` of it (``runner.spin_s``, where
    that is shorter; a ``--spin-s`` of the layout still wins). Every other key keeps its
    default: a file is merged over the defaults key by key."""
    from haptic.common.config import load_config

    defaults = load_config()
    text = f"[model]\nsample_period_s = {period_s!r}\n"
    if period_s < defaults["model"]["sample_period_s"]:
        spin_s = min(defaults["runner"]["spin_s"], SHORT_PERIOD_SPIN_SHARE * period_s)
        text += f"[runner]\nspin_s = {spin_s!r}\n"
    path = folder / "period.toml"
    path.write_text(text)
    return path


def default_cpu_layout(args: argparse.Namespace, ts_s: float) -> str:
    """The layout when ``--cpu-layout`` is not given: ``free`` for the echo nodes and custom
    commands (no phase lock) and for a period under the configured one (there the two
    programs' steps do not fit one CPU's period: docs/measurements/loop_bench.md); else
    ``partitioned``."""
    if args.echo or args.master_cmd or args.slave_cmd:
        return LOOPS_FIFO_ANYWHERE.name
    from haptic.common.config import load_config

    return (LOOPS_FIFO_ANYWHERE.name if ts_s < load_config()["model"]["sample_period_s"]
            else LOOPS_SHARING_ONE_CPU.name)


def _run(args: argparse.Namespace, extra: list[str], ts_s: float) -> dict[str, Any]:
    return benchmark(
        args.duration,
        shlex.split(args.master_cmd) if args.master_cmd else None,
        shlex.split(args.slave_cmd) if args.slave_cmd else None,
        extra,
        ts_s=ts_s,
        echo=args.echo,
        rig=args.rig,
        cpu_layout=args.cpu_layout or default_cpu_layout(args, ts_s),
        cpu_latency_limit_us=args.cpu_latency_us,
    )


if __name__ == "__main__":
    sys.exit(main())
