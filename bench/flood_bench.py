"""Flood benchmark (issue 17): ``haptic-master --rig model`` and ``haptic-slave`` on loopback,
and a third process flooding the master's receive key (``<prefix>/tool``) with 50-byte junk at
``--rate`` Hz for ``--flood`` s in the middle of the run.

Reports the master's tick rate inside the flood window (from its trace: every
``--trace-every``-th tick's time) and over the whole run, the watchdog trips of both sides,
the master's malformed-message count and how many polls reached the flood bound
(``[link.security] max_samples_per_poll``). Figures only; nothing is asserted (timing depends
on the machine). Target (issue 17): >= 1845 Hz in the window and no watchdog trip under a
50 kHz flood.

Usage: ``python bench/flood_bench.py [--rate HZ] [--flood S] [--max-samples N] [--json]``.
"""

from __future__ import annotations

import argparse
import json
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


def run(rate_hz: float, flood_s: float, max_samples: int, lead_s: float = 6.0) -> dict:
    endpoint = f"tcp/127.0.0.1:{_free_port()}"
    prefix = f"bench/{uuid.uuid4().hex[:8]}"
    duration_s = lead_s + flood_s + 3.0
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        config = tmp / "config.toml"
        config.write_text(f'[slave]\nscenario = "constant-rate"\nenvironment = "linear"\n'
                          f'clay_impl = "numpy"\ndevice = "cpu"\n\n[link.security]\n'
                          f"max_samples_per_poll = {max_samples}\n")
        common = ["--config", str(config), "--key-prefix", prefix, "--no-status",
                  "--peer-wait", "60", "--duration", str(duration_s)]
        processes = []
        try:
            master = subprocess.Popen(
                [sys.executable, "-m", "haptic.master.cli", *common, "--listen", endpoint,
                 "--rig", "model", "--json-summary", str(tmp / "master.json"),
                 "--out", str(tmp), "--trace-every", "10"],
                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
            processes.append(master)
            slave = subprocess.Popen(
                [sys.executable, "-m", "haptic.slave_sim.cli", *common, "--connect",
                 endpoint, "--json-summary", str(tmp / "slave.json")],
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, text=True)
            processes.append(slave)
            # the master prints "waiting for the slave" once its link is open
            assert master.stderr is not None
            while "waiting for the slave" not in master.stderr.readline():
                if master.poll() is not None:
                    raise RuntimeError("haptic-master ended before its link opened")
            time.sleep(lead_s)
            flood_start_s = time.time()
            flooder = subprocess.Popen(
                [sys.executable, "-m", "tests.wire.attacks", "junk", "--connect", endpoint,
                 "--key-prefix", prefix, "--rate", str(rate_hz), "--duration", str(flood_s)],
                stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                cwd=Path(__file__).resolve().parents[1])
            processes.append(flooder)
            flood_out, _ = flooder.communicate(timeout=flood_s + 60)
            flood_end_s = time.time()
            master.communicate(timeout=duration_s + 60)
            slave.communicate(timeout=60)
        finally:
            for process in processes:
                if process.poll() is None:
                    process.kill()
                process.wait(timeout=10)
        summary_m = json.loads((tmp / "master.json").read_text())
        summary_s = json.loads((tmp / "slave.json").read_text())
        trace = np.load(tmp / "master_trace.npz")
        times = trace["time_s"] + summary_m["loop_start_time_s"]
        # the flooder's own start-up (~1 s) is inside [flood_start, flood_end]
        window = (times >= flood_start_s + 1.0) & (times <= flood_end_s)
        span = times[window]
        window_rate = (10 * (span.size - 1) / (span[-1] - span[0])
                       if span.size > 1 and span[-1] > span[0] else float("nan"))
    sent = int(flood_out.split()[-1]) if flood_out.strip() else 0
    return {
        "flood_rate_hz": rate_hz, "flood_s": flood_s, "flood_sent": sent,
        "flood_achieved_hz": sent / flood_s, "max_samples_per_poll": max_samples,
        "master_rate_in_flood_hz": window_rate, "master_rate_hz": summary_m["rate_hz"],
        "master_watchdog_trips": summary_m["watchdog_trips"],
        "slave_watchdog_trips": summary_s["watchdog_trips"],
        "master_malformed": summary_m["link_dropped"]["malformed"],
        "master_capped_polls": summary_m.get("link_capped_polls"),
        "slave_malformed": summary_s["link_dropped"]["malformed"],
        "master_overruns": summary_m.get("overruns"),
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rate", type=float, default=50000.0, help="junk messages per s")
    parser.add_argument("--flood", type=float, default=3.0, help="flood length, s")
    parser.add_argument("--max-samples", type=int, default=64,
                        help="[link.security] max_samples_per_poll")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    result = run(args.rate, args.flood, args.max_samples)
    if args.json:
        print(json.dumps(result))
    else:
        for key, value in result.items():
            print(f"{key:28s} {value}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
