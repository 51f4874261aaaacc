"""Memory of a long recorded run: ``haptic-master --rig model`` and
``haptic-slave`` on loopback, both with ``--record``, for ``--duration`` s (default 600,
10 minutes); each process's RSS sampled every second from /proc. Reports the RSS at
the start and the end of the measured span and the growth rate (least squares over the run
after ``--settle`` s), kB/s, and the same slope over the first and the second half of that
span (a leak keeps its slope; a warm-up flattens), with the growth over the last 5 minutes,
and the RSS every ~10 s (``*_rss_series_kB``). Figures only.

What it showed, run by run, with the machine and the date of each: docs/measurements/
record_memory.md.

``--no-record`` runs the same without recording (the reference: what the recording adds).

Usage: ``python bench/record_memory_bench.py [--duration S] [--settle S] [--linear]
[--no-record] [--json]``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

import numpy as np

from haptic.common.wire.ports import free_port as _free_port


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
    parser = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
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
