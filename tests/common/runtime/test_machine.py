"""What the programs read of the machine: usable CPUs and another process's CPU time."""

from __future__ import annotations

import os
import sys
import time

import pytest

from haptic.common.runtime.machine import process_cpu_s, usable_cpu_count
from tests.helpers.programs import Program


def test_usable_cpus_are_those_this_process_may_run_on() -> None:
    count = usable_cpu_count()
    assert 1 <= count <= (os.cpu_count() or count)
    if hasattr(os, "sched_getaffinity"):
        assert count == len(os.sched_getaffinity(0))


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="needs Linux /proc")
def test_another_process_cpu_time_grows_while_it_works_and_is_none_once_gone() -> None:
    """A child that burns 0.3 s of its own CPU time shows at least 0.2 s more in /proc (clock-tick
    resolution) than when it started; once reaped, its PID reads as None."""
    with Program([sys.executable, "-c",
                  "import sys, time\nprint('go', flush=True)\nsys.stdin.readline()\n"
                  "until = time.process_time() + 0.3\nwhile time.process_time() < until: pass\n"
                  "print('done', flush=True)\nsys.stdin.readline()\n"], stdin=True) as child:
        child.wait_for(r"^go$", timeout_s=120.0)
        before = process_cpu_s(child.pid)
        assert before is not None and before >= 0.0
        child.write_line("")
        child.wait_for(r"^done$", timeout_s=120.0)
        after = process_cpu_s(child.pid)
        assert after is not None and after - before >= 0.2
        child.write_line("")
        assert child.wait(timeout_s=30) == 0
    deadline = time.monotonic() + 5.0
    while process_cpu_s(child.pid) is not None and time.monotonic() < deadline:
        time.sleep(0.05)  # the PID is free once reaped (barring reuse, not in 5 s)
    assert process_cpu_s(child.pid) is None
