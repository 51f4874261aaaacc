"""Benchmark of the interfaces: the recorder's cost in the loop, its writer's throughput, and
the live view's update rate during a real run.

1. Recorder, loop side: the time of one ``RunRecording.state`` call (what the loop pays per
   tick with ``--record``), and the writer thread's throughput (messages encoded and written
   per second) with its drops at a given queue size.
2. A networked run on loopback (``haptic-slave`` cutting clay, ``haptic-master`` with the
   regulating operator, both with ``--record``, and ``haptic-view``): frames per second that
   one SSE client of the view receives, the view's state update rate, the recorders' drops
   and the slave's display-publication cost (s per publication, mean and largest).
3. ``--browser``: the loops with the view serving one headless Chromium page (Debian's
   ``chromium`` driven by Playwright), with the display's back-off on (the default) and off
   (``[runner] display_backoff = false``, ``haptic-view --no-backoff``), against the same
   run without the view: each loop's rate, overruns and watchdog trips, the frames and
   drawings the page made, and the lowest scale the view and the display threads backed off
   to (common/runtime/display_backoff.py).

    python bench/view_bench.py [--duration S] [--browser] [--json]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
import urllib.request
import uuid
from pathlib import Path

from haptic.common.records.run_recording import RunRecording
from haptic.common.wire.ports import free_port as _free_port


def recorder_figures(calls: int = 50_000) -> dict[str, float]:
    """Loop-side cost per call and the writer's throughput, with 17 columns as the slave."""
    from haptic.slave_sim.program import SLAVE_RECORD_COLUMNS

    values = tuple(float(i) for i in range(len(SLAVE_RECORD_COLUMNS)))
    with tempfile.TemporaryDirectory() as folder:
        recording = RunRecording(Path(folder) / "bench.mcap", "slave", SLAVE_RECORD_COLUMNS,
                                 0.00054, queue_size=calls + 10)
        recording.start(time.time_ns(), time.perf_counter_ns(), None)
        state = recording.state
        costs = []
        for block in range(calls // 1000):
            started = time.perf_counter_ns()
            for i in range(1000):
                state(block * 1000 + i, time.perf_counter_ns(), values)
            costs.append((time.perf_counter_ns() - started) / 1000)
        write_start = time.perf_counter()
        figures = recording.close(time.time_ns(), None)
        drain_s = time.perf_counter() - write_start
    costs.sort()
    return {"record_call_mean_s": sum(costs) / len(costs) * 1e-9,
            "record_call_p99_block_s": costs[int(0.99 * (len(costs) - 1))] * 1e-9,
            "writer_messages": figures["record_written"],
            "writer_drain_after_loop_s": drain_s,
            "writer_messages_per_s_lower_bound": figures["record_written"] / max(drain_s, 1e-9)}


def _reap(processes: list[subprocess.Popen]) -> None:
    """End the children still running (by their own PIDs) and reap every one."""
    for process in processes:
        if process.poll() is None:
            process.kill()
        process.wait(timeout=10)


def _pair_figures(tmp: Path) -> tuple[dict, dict, dict[str, float]]:
    """The master's and the slave's summaries in ``tmp`` and both loops' figures."""
    master = json.loads((tmp / "master.json").read_text())
    slave = json.loads((tmp / "slave.json").read_text())
    return master, slave, {**_loop_figures(master, "master", slave),
                           **_loop_figures(slave, "slave", master)}


def pair_figures(duration_s: float, record: bool, display: bool) -> dict[str, float]:
    """The same networked run without the view, with or without ``--record`` and the display
    publications: the loops' rate and overruns, to attribute the cost."""
    tmp = Path(tempfile.mkdtemp(prefix="view-bench-pair-"))
    endpoint = f"tcp/127.0.0.1:{_free_port()}"
    common = ["--key-prefix", f"bench/{uuid.uuid4().hex[:8]}",
              "--display" if display else "--no-display"]
    run = ["--no-status", "--peer-wait", "30", "--duration", str(duration_s)]
    record_m = ["--record", str(tmp / "master.mcap")] if record else []
    record_s = ["--record", str(tmp / "slave.mcap")] if record else []
    processes = [
        subprocess.Popen([sys.executable, "-m", "haptic.master.cli", *common, *run, "--listen",
                          endpoint, "--rig", "model", "--operator",
                          "regulate:fx=3.6,onset=0.2,max=5", *record_m, "--json-summary",
                          str(tmp / "master.json")], stderr=subprocess.DEVNULL),
        subprocess.Popen([sys.executable, "-m", "haptic.slave_sim.cli", *common, *run,
                          "--connect", endpoint, *record_s, "--json-summary",
                          str(tmp / "slave.json")], stderr=subprocess.DEVNULL),
    ]
    try:
        for process in processes:
            process.wait(timeout=duration_s + 90)
    finally:
        _reap(processes)
    master, slave, loops = _pair_figures(tmp)
    return {**loops,
            "master_steps": master["steps"], "slave_steps": slave["steps"]}


def run_figures(duration_s: float) -> dict[str, float]:
    """The networked run with the view (see the module docstring)."""
    tmp = Path(tempfile.mkdtemp(prefix="view-bench-"))
    endpoint = f"tcp/127.0.0.1:{_free_port()}"
    prefix = f"bench/{uuid.uuid4().hex[:8]}"
    port = _free_port()
    common = ["--key-prefix", prefix]
    run = ["--no-status", "--peer-wait", "30", "--duration", str(duration_s)]
    processes = [
        subprocess.Popen([sys.executable, "-m", "haptic.view.cli", *common, "--connect",
                          endpoint, "--port", str(port)], stderr=subprocess.DEVNULL),
        subprocess.Popen([sys.executable, "-m", "haptic.master.cli", *common, *run, "--listen",
                          endpoint, "--rig", "model", "--operator",
                          "regulate:fx=3.6,onset=0.2,max=5", "--record",
                          str(tmp / "master.mcap"), "--json-summary", str(tmp / "master.json")],
                         stderr=subprocess.DEVNULL),
        subprocess.Popen([sys.executable, "-m", "haptic.slave_sim.cli", *common, *run,
                          "--connect", endpoint, "--record", str(tmp / "slave.mcap"),
                          "--json-summary", str(tmp / "slave.json")],
                         stderr=subprocess.DEVNULL),
    ]
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/state", timeout=1) as r:
                    if json.loads(r.read())["tool"] is not None:
                        break
            except OSError:
                pass
            time.sleep(0.1)
        frames = 0
        window = max(1.0, duration_s / 2)
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/events", timeout=5) as stream:
            started = time.monotonic()
            while time.monotonic() - started < window:
                line = stream.readline()
                if line.startswith(b"data: "):
                    frames += 1
            elapsed = time.monotonic() - started
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/stats", timeout=5) as r:
            stats = json.loads(r.read())
        for process in processes[1:]:
            process.wait(timeout=duration_s + 60)
    finally:
        _reap(processes)
    master, slave, _ = _pair_figures(tmp)
    return {"view_frames_per_s": frames / elapsed,
            "view_state_updates_per_s_since_start": stats["state_update_rate_hz"],
            "master_rate_hz": master["rate_hz"], "slave_rate_hz": slave["rate_hz"],
            "master_overruns": master["overruns"], "slave_overruns": slave["overruns"],
            "master_steps": master["steps"], "slave_steps": slave["steps"],
            "master_record_written": master["record_written"],
            "master_record_dropped": master["record_dropped"],
            "slave_record_written": slave["record_written"],
            "slave_record_dropped": slave["record_dropped"],
            "slave_display_publications": slave.get("display_publications"),
            "slave_display_mean_cost_s": slave.get("display_mean_cost_s"),
            "slave_display_max_cost_s": slave.get("display_max_cost_s")}


CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu",
                 "--disable-background-networking", "--disable-component-update",
                 "--disable-sync", "--no-first-run"]


def _loop_figures(summary: dict, side: str, peer: dict) -> dict[str, float]:
    """A loop's figures from its summary; its watchdog trips during the run (a trip when
    the peer stops first at the end is not one: haptic-session's rule)."""
    from haptic.common.launch.cli import watchdog_trips_split

    return {f"{side}_rate_hz": summary["rate_hz"], f"{side}_overruns": summary["overruns"],
            f"{side}_overrun_ratio": summary["overrun_ratio"],
            f"{side}_watchdog_trips_during_run": watchdog_trips_split(summary, peer)[0],
            f"{side}_display_lowest_scale": summary.get("display_lowest_scale")}


def browser_figures(duration_s: float, backoff: bool, chromium: str) -> dict[str, float]:
    """The networked run (the ``model`` rig, no recording) with the view and one headless
    Chromium page on it, the display's back-off on or off; the page's frames and drawings
    over the loops' run."""
    from playwright import sync_api

    tmp = Path(tempfile.mkdtemp(prefix="view-bench-browser-"))
    config = tmp / "config.toml"
    config.write_text(f"[runner]\ndisplay_backoff = {'true' if backoff else 'false'}\n")
    master_port = _free_port()
    endpoint = f"tcp/127.0.0.1:{master_port}"
    port = _free_port()
    common = ["--config", str(config), "--key-prefix", f"bench/{uuid.uuid4().hex[:8]}"]
    run = ["--no-status", "--peer-wait", "30", "--duration", str(duration_s)]
    processes = [subprocess.Popen(
        [sys.executable, "-m", "haptic.master.cli", *common, *run, "--listen", endpoint,
         "--rig", "model", "--operator", "regulate:fx=3.6,onset=0.2,max=5", "--json-summary",
         str(tmp / "master.json")], stderr=subprocess.DEVNULL)]
    try:
        processes.append(subprocess.Popen(
            [sys.executable, "-m", "haptic.view.cli", *common, "--connect", endpoint, "--port",
             str(port), *([] if backoff else ["--no-backoff"])], stderr=subprocess.DEVNULL))
        url = f"http://127.0.0.1:{port}/"
        deadline = time.monotonic() + 60
        while True:
            try:
                with urllib.request.urlopen(url, timeout=1):
                    break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.1)
        with sync_api.sync_playwright() as playwright:
            browser = playwright.chromium.launch(executable_path=chromium, headless=True,
                                                 args=CHROMIUM_ARGS)
            try:
                page = browser.new_page(viewport={"width": 1300, "height": 700})
                page.goto(url)
                processes.append(subprocess.Popen(
                    [sys.executable, "-m", "haptic.slave_sim.cli", *common, *run,
                     "--connect", endpoint, "--json-summary", str(tmp / "slave.json")],
                    stderr=subprocess.DEVNULL))
                started = time.monotonic()
                while processes[2].poll() is None and time.monotonic() - started < (
                        duration_s + 60):
                    page.wait_for_timeout(200)
                seen = page.evaluate("({frames: hapticView.frames, draws: hapticView.draws})")
                elapsed = time.monotonic() - started
            finally:
                browser.close()
        with urllib.request.urlopen(url + "stats", timeout=5) as response:
            stats = json.loads(response.read())
        processes[0].wait(timeout=60)
    finally:
        _reap(processes)
    _, _, loops = _pair_figures(tmp)
    return {**loops,
            "page_frames_per_s": seen["frames"] / elapsed,
            "page_draws_per_s": seen["draws"] / elapsed,
            "view_lowest_frame_scale": stats["lowest_frame_scale"]}


def main() -> int:
    parser = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.split("\n")[0])
    parser.add_argument("--duration", type=float, default=6.0, help="networked run, s")
    parser.add_argument("--browser", action="store_true",
                        help="only the runs with a headless Chromium page on the view, the "
                        "back-off on and off, and the same run without the view")
    parser.add_argument("--chromium", default="/usr/bin/chromium", help="Chromium executable")
    parser.add_argument("--rounds", type=int, default=1, help="--browser: runs of each")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    if args.browser:
        figures = {}
        for round_index in range(args.rounds):  # interleaved: the machine's load drifts
            suffix = f" #{round_index + 1}" if args.rounds > 1 else ""
            figures[f"view + page, back-off on{suffix}"] = browser_figures(
                args.duration, True, args.chromium)
            figures[f"view + page, back-off off{suffix}"] = browser_figures(
                args.duration, False, args.chromium)
            figures[f"no view (display on){suffix}"] = pair_figures(args.duration, False, True)
    else:
        figures = {"recorder": recorder_figures(), "run": run_figures(args.duration),
                   "record only (no view, no display)": pair_figures(args.duration, True,
                                                                     False),
                   "display only (no view, no record)": pair_figures(args.duration, False,
                                                                     True),
                   "baseline (no view, no display, no record)":
                       pair_figures(args.duration, False, False)}
    if args.json:
        print(json.dumps(figures, indent=2))
        return 0
    if "recorder" in figures:
        r = figures["recorder"]
        print(f"recorder, loop side: {r['record_call_mean_s'] * 1e6:.2f} us per tick (mean), "
              f"{r['record_call_p99_block_s'] * 1e6:.2f} us (p99 of 1000-call blocks)")
        print(f"recorder, writer: {r['writer_messages']} messages drained in "
              f"{r['writer_drain_after_loop_s']:.2f} s after the loop")
    for title in figures:
        if title == "recorder":
            continue
        print("record, display and view:" if title == "run" else f"{title}:")
        for key, value in figures[title].items():
            print(f"  {key}: {value:.6g}" if isinstance(value, float) else f"  {key}: {value}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
