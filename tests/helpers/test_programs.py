"""The tests' program launcher (tests/helpers/programs.py) on small ``python -c`` children: it
finds a line within its deadline, ends a child by its PID with the signal asked for, falls back
to SIGKILL after the grace period, and always reaps."""

from __future__ import annotations

import os
import signal
import sys
import time

import pytest

from tests.helpers.programs import Program, Programs, run_to_end

#: A child that says it is ready, then ends with status 0 on SIGINT.
READY_UNTIL_SIGINT = (
    "import signal, sys, time\n"
    "signal.signal(signal.SIGINT, lambda *_: sys.exit(0))\n"
    "print('ready', flush=True)\n"
    "time.sleep(60)\n"
)

#: A child that ignores SIGINT and SIGTERM once it has said so.
DEAF = (
    "import signal, time\n"
    "signal.signal(signal.SIGINT, signal.SIG_IGN)\n"
    "signal.signal(signal.SIGTERM, signal.SIG_IGN)\n"
    "print('deaf', flush=True)\n"
    "time.sleep(60)\n"
)


def _reaped(pid: int) -> bool:
    """Whether ``pid`` is no longer a child of this process (reaped, no zombie left)."""
    try:
        os.waitpid(pid, os.WNOHANG)
    except ChildProcessError:
        return True
    return False


def test_a_line_is_found_and_sigint_ends_the_child_by_its_pid() -> None:
    with Program([sys.executable, "-c", READY_UNTIL_SIGINT]) as child:
        found = child.wait_for(r"^(ready)$", timeout_s=30.0)
        assert found.group(1) == "ready"
        assert child.stop() == 0
        assert _reaped(child.pid)


def test_a_child_deaf_to_the_signal_is_killed_after_the_grace_period() -> None:
    child = Program([sys.executable, "-c", DEAF])
    try:
        child.wait_for("deaf", timeout_s=30.0)
        started = time.monotonic()
        assert child.stop(signal.SIGTERM, grace_s=0.5) == -signal.SIGKILL
        assert 0.5 <= time.monotonic() - started < 10.0
    finally:
        child.close()
    assert _reaped(child.pid)


def test_a_missing_line_fails_at_the_end_of_the_output_with_the_output() -> None:
    with Program([sys.executable, "-c", "print('something else')"]) as child:
        with pytest.raises(AssertionError, match="something else"):
            child.wait_for("ready", timeout_s=30.0)
        assert child.wait(timeout_s=30.0) == 0


def test_a_missing_line_fails_at_the_deadline() -> None:
    with Program([sys.executable, "-c", READY_UNTIL_SIGINT]) as child:
        started = time.monotonic()
        with pytest.raises(AssertionError, match="not within 0.3 s"):
            child.wait_for("never", timeout_s=0.3)
        assert time.monotonic() - started < 10.0
    assert child.returncode == 0


def test_output_env_and_stdin_reach_the_child() -> None:
    script = "import os, sys\nprint(os.environ['PROGRAM_TEST'], sys.stdin.readline().strip())\n"
    with Program([sys.executable, "-c", script], env={"PROGRAM_TEST": "set"},
                 stdin=True) as child:
        child.write_line("read")
        assert child.wait(timeout_s=30.0) == 0
        assert child.output() == "set read\n"


def test_a_chatty_child_never_blocks_on_its_pipe() -> None:
    script = "import sys\nsys.stdout.write('x' * 4_000_000)\nsys.stderr.write('end')\n"
    with Program([sys.executable, "-c", script]) as child:
        assert child.wait(timeout_s=60.0) == 0
        assert len(child.output()) == 4_000_003


def test_programs_end_every_child_even_when_one_already_ended() -> None:
    with Programs() as programs:
        done = programs.start([sys.executable, "-c", "pass"])
        waiting = programs.start([sys.executable, "-c", READY_UNTIL_SIGINT])
        waiting.wait_for("ready", timeout_s=30.0)
        assert done.wait(timeout_s=30.0) == 0
    assert waiting.returncode == 0 and done.returncode == 0
    assert _reaped(waiting.pid) and _reaped(done.pid)


def test_run_to_end_keeps_stdout_and_stderr_apart() -> None:
    script = "import sys\nprint('out')\nprint('err', file=sys.stderr)\nsys.exit(3)\n"
    result = run_to_end([sys.executable, "-c", script], timeout_s=30.0)
    assert (result.returncode, result.stdout, result.stderr) == (3, "out\n", "err\n")


def test_run_to_end_fails_at_its_deadline_with_the_output_and_reaps() -> None:
    script = "import time\nprint('started', flush=True)\ntime.sleep(60)\n"
    started = time.monotonic()
    with pytest.raises(AssertionError, match="(?s)still running after 1.0 s.*started"):
        run_to_end([sys.executable, "-c", script], timeout_s=1.0)
    assert time.monotonic() - started < 30.0


def test_the_first_program_to_end_is_found_and_none_ending_fails() -> None:
    with Programs() as programs:
        waiting = programs.start([sys.executable, "-c", READY_UNTIL_SIGINT])
        waiting.wait_for("ready", timeout_s=30.0)
        with pytest.raises(AssertionError, match="none of the programs ended within 0.2 s"):
            programs.first_to_end(timeout_s=0.2)
        done = programs.start([sys.executable, "-c", "print('done')"])
        assert programs.first_to_end(timeout_s=30.0) is done
        assert done.returncode == 0 and waiting.running()
