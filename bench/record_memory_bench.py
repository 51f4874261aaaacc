"""Memory of a long recorded run (issue 17): ``haptic-master --rig model`` and
``haptic-slave`` on loopback, both with ``--record``, for ``--duration`` s (default 600: the
issue's 10 minutes); each process's RSS sampled every second from /proc. Reports the RSS at
the start and the end of the measured span and the growth rate (least squares over the run
after ``--settle`` s), kB/s, and the same slope over the first and the second half of that
span (a leak keeps its slope; a warm-up flattens), with the growth over the last 5 minutes,
and the RSS every ~10 s (``*_rss_series_kB``). Figures only.

What it showed (issue 17; 2-core VM shared with other work, load average 6-10): the 2-3 minute
slopes (18-57 kB/s for the slave, with *and* without ``--record``) are the start's, not a
leak. tracemalloc: the Python heap of the recorded slave's loop is flat; the slave's node and
Warp clay stepped alone grow 0 kB over 250k steps; two Links exchanging at 1850 Hz keep
+12 kB of Python objects. The RSS that grows lives in glibc's per-thread arenas of Zenoh's
threads (``/proc/PID/smaps``), is not given back by ``malloc_trim`` and slows down: over 10
minutes the slave's slope in the second half was 0.95 kB/s recorded and 2.7 kB/s not (the
master's 2.4 and 0.06). What recording itself kept was the MCAP writer's chunk index (one
``ChunkIndex`` of about 370 B per chunk, written into the summary at the end): the recorder
now spills them to an unnamed file beside the recording (common/records/recorder.py). Two
10-minute recorded runs after that (``--env MALLOC_ARENA_MAX=2``, 2-core AMD EPYC, nothing
else running): the slave flat (0.0 and 0.05 kB/s, +0 and +28 kB over the last 5 minutes;
before: 0.59 kB/s, 1.7 in the second half); the master 1.3 and 1.6 kB/s (+252 and +668 kB
over the last 5 minutes; before: 3.0 kB/s), its growth in glibc's main heap and the arena its
threads share (``/proc/PID/smaps``), not found in our objects. One 10-minute run without
recording, on a machine then at load 10, grew 25 MB in both programs in its second half:
rerun before trusting one run.

Where the master's growth lives (2026-12-02, the same 2-core AMD EPYC, nothing else running):
memray (``memray run --aggregate --native``, ``PYTHONMALLOC=malloc``; every allocation of
Python, numpy, msgpack and Zenoh's Rust code) on the recorded master for 40 s and for 160 s:
its live heap held at 196.8-197.4 MB from 70 s to the end, and no allocation site held more
at the high-water mark or at exit in the longer run beyond a few kB (the run's events). The
RSS the master adds is therefore memory the allocators keep, not live data. 10-minute runs
from 30 s on: the master +1.3 MB (1.6 kB/s in the second half, in steps of 100-500 kB, +332 kB
over the last 5 minutes), the slave +360 kB (1.1 kB/s, +236 kB); with ``--env
PYTHONMALLOC=malloc`` (no pymalloc arenas) +2.2 MB and +1.2 MB, most of it in the first
minutes (0.78 and 0.0 kB/s in the second half, +204 and +0 kB over the last 5 minutes): not
adopted, pymalloc is faster per object. 5-minute runs with ``MALLOC_MMAP_THRESHOLD_`` and
``MALLOC_TRIM_THRESHOLD_`` fixed at 128 kB grew the slave 4 kB/s (worse) and the master as
without.

A 30-minute recorded run (``--duration 1800``, 2026-12-05, a 2-core Intel Xeon KVM guest,
nothing else running; 160 MB of MCAP from the master, 174 MB from the slave): the master's
RSS 334.5 -> 335.6 MB over the fit (0.07 kB/s; 0.20 kB/s in the first half, 0.02 in the
second, +0 kB over the last 5 minutes), the slave's 343.5 -> 344.7 MB (0.07 kB/s; 0.22, then
0.0; +0 kB); from 2 minutes on the master grew 88 kB and the slave 152 kB, the slave none
after 10 minutes. The allocators' retention levels off: memory is flat.

``--no-record`` runs the same without recording (the reference: what the recording adds).

Usage: ``python bench/record_memory_bench.py [--duration S] [--settle S] [--linear]
[--no-record] [--json]``.
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

import numpy as np


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _rss_kb(pid: int) -> float | None:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return float(line.split()[1])
    except OSError:
        return None
    return None


def run(duration_s: float, settle_s: float, linear: bool, record: bool = True,
        env: dict[str, str] | None = None) -> dict:
    endpoint = f"tcp/127.0.0.1:{_free_port()}"
    prefix = f"bench/{uuid.uuid4().hex[:8]}"
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        common = ["--key-prefix", prefix, "--no-status", "--peer-wait", "60", "--duration",
                  str(duration_s), "--no-display"]
        if linear:
            config = tmp / "linear.toml"
            config.write_text('[slave]\nscenario = "constant-rate"\nenvironment = "linear"\n'
                              'clay_impl = "numpy"\ndevice = "cpu"\n')
            common += ["--config", str(config)]
        environ = {**os.environ, **(env or {})}
        processes = {}
        samples: dict[str, list[tuple[float, float]]] = {"master": [], "slave": []}
        try:
            processes["master"] = subprocess.Popen(
                [sys.executable, "-m", "haptic.master.cli", *common, "--listen", endpoint,
                 "--rig", "model", *(["--record", str(tmp / "master.mcap")] if record else []),
                 "--json-summary", str(tmp / "master.json")],
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=environ)
            processes["slave"] = subprocess.Popen(
                [sys.executable, "-m", "haptic.slave_sim.cli", *common, "--connect",
                 endpoint, *(["--record", str(tmp / "slave.mcap")] if record else []),
                 "--json-summary", str(tmp / "slave.json")],
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=environ)
            start = time.monotonic()
            while any(p.poll() is None for p in processes.values()):
                now = time.monotonic() - start
                for side, process in processes.items():
                    rss = _rss_kb(process.pid) if process.poll() is None else None
                    if rss is not None:
                        samples[side].append((now, rss))
                time.sleep(1.0)
                if now > duration_s + 120:
                    break
        finally:
            for process in processes.values():
                if process.poll() is None:
                    process.kill()
                process.wait(timeout=10)
        sizes = {side: (tmp / f"{side}.mcap").stat().st_size
                 for side in processes if (tmp / f"{side}.mcap").exists()}
        recorder = {}
        for side in processes:
            path = tmp / f"{side}.json"
            if path.exists():
                summary = json.loads(path.read_text())
                recorder[side] = {k: summary.get(k) for k in (
                    "record_max_queue_depth", "record_dropped", "rate_hz")}
    result: dict = {"duration_s": duration_s, "settle_s": settle_s, "linear": linear,
                    "record": record, "env": env or {}}
    for side, points in samples.items():
        data = np.array(points)
        if data.size == 0:
            continue
        # the run's own span: from settle_s after the first sample to 5 s before the last
        keep = (data[:, 0] >= data[0, 0] + settle_s) & (data[:, 0] <= data[-1, 0] - 5.0)
        span = data[keep]
        if len(span) >= 6:
            slope = float(np.polyfit(span[:, 0], span[:, 1], 1)[0])
            result[f"{side}_rss_start_kB"] = float(span[0, 1])
            result[f"{side}_rss_end_kB"] = float(span[-1, 1])
            result[f"{side}_rss_growth_kB_per_s"] = slope
            # a leak grows as fast in the second half as in the first; a warm-up (allocator
            # arenas, buffer pools filling) slows down and stops
            half = len(span) // 2
            for name, part in (("first_half", span[:half]), ("second_half", span[half:])):
                result[f"{side}_rss_growth_{name}_kB_per_s"] = float(
                    np.polyfit(part[:, 0], part[:, 1], 1)[0])
            last = span[span[:, 0] >= span[-1, 0] - 300.0]  # the last 5 minutes
            result[f"{side}_rss_growth_last_5min_kB"] = float(last[-1, 1] - last[0, 1])
        # the RSS every ~10 s of the run (s since the start, kB): where a growth happened
        series = data[:: max(1, round(10.0 / max(np.median(np.diff(data[:, 0])), 1e-3)))]
        result[f"{side}_rss_series_kB"] = [[round(float(t), 1), float(r)] for t, r in series]
        result[f"{side}_record_bytes"] = sizes.get(side)
        result[f"{side}_recorder"] = recorder.get(side)
    return result


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=600.0)
    parser.add_argument("--settle", type=float, default=30.0,
                        help="seconds after the start not in the fit (start-up, allocations)")
    parser.add_argument("--linear", action="store_true",
                        help="the slave with the linear environment (no Warp clay)")
    parser.add_argument("--no-record", action="store_true",
                        help="both programs without --record (the reference)")
    parser.add_argument("--env", action="append", default=[], metavar="NAME=VALUE",
                        help="an environment variable for both programs (repeatable), e.g. "
                        "MALLOC_ARENA_MAX=2")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    env = dict(item.split("=", 1) for item in args.env)
    result = run(args.duration, args.settle, args.linear, not args.no_record, env)
    if args.json:
        print(json.dumps(result))
    else:
        for key, value in result.items():
            if not key.endswith("_series_kB"):
                print(f"{key:40s} {value}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
