"""The one way tests start a program (``haptic-master``, ``haptic-slave``, ``haptic-session``,
a router, a ``python -c`` child) and always end it.

A :class:`Program` is a child process whose output (stdout and stderr merged, text) a thread
reads as it comes, so a chatty child never blocks on a full pipe and a test can wait for a line
with a deadline. It is ended by its own PID only (never a process group or a name): the signal
asked for, then SIGKILL after a grace period; it is always reaped and its pipes closed, also
when the test fails. Every wait is bounded and a wait that runs out fails the test with the
output so far. :func:`run_to_end` runs a short program to its end with stdout and stderr
apart, for a test that tells them apart."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from types import TracebackType

#: How long a program may take to end after the signal that asks it to, s, before SIGKILL.
DEFAULT_GRACE_S = 10.0

#: How much of a program's output a failure message quotes (its tail), characters.
QUOTED_OUTPUT_CHARS = 4000


def python_module(module: str, *args: str) -> list[str]:
    """The command line running ``module`` with this interpreter (``python -m module args``),
    so a test runs the code of this checkout whatever is on PATH."""
    return [sys.executable, "-m", module, *args]


def run_to_end(args: Sequence[str], timeout_s: float, *, env: Mapping[str, str] | None = None,
               cwd: Path | str | None = None) -> subprocess.CompletedProcess[str]:
    """Run ``args`` to its end with its stdout and stderr apart (text), for a test that tells
    them apart; stdin reads nothing, ``env`` as for :class:`Program`. Fails with both outputs
    when it runs past ``timeout_s`` s (then killed by its own PID and reaped)."""
    environment = {**os.environ, **env} if env is not None else None
    command = [str(arg) for arg in args]
    try:
        return subprocess.run(command, capture_output=True, text=True, timeout=timeout_s,
                              stdin=subprocess.DEVNULL, env=environment, cwd=cwd, check=False)
    except subprocess.TimeoutExpired as expired:  # subprocess.run killed and reaped it
        output = _text(expired.stdout) + _text(expired.stderr)
        raise AssertionError(f"still running after {timeout_s} s ({' '.join(command)}); "
                             f"its output ends:\n{output[-QUOTED_OUTPUT_CHARS:]}") from None


def _text(output: str | bytes | None) -> str:
    """What a timed-out run captured (bytes when cut off mid-character), as text."""
    if isinstance(output, bytes):
        return output.decode(errors="replace")
    return output or ""


class Program:
    """A started child process (see the module's docstring). Use it as a context manager, or
    call :meth:`close`, so that it is ended and reaped whatever the test does."""

    def __init__(self, args: Sequence[str], *, env: Mapping[str, str] | None = None,
                 cwd: Path | str | None = None, stdin: bool = False,
                 stop_signal: int = signal.SIGINT, new_session: bool = False) -> None:
        """Start ``args``. ``env`` adds to (or overrides) this process's environment;
        ``stdin`` gives the child a pipe to write to (:meth:`write_line`), else it reads
        nothing; ``stop_signal`` is what :meth:`close` asks it to end with; ``new_session``
        puts it in a session of its own, out of reach of a signal to the tests' terminal."""
        self.args = [str(arg) for arg in args]
        self.stop_signal = stop_signal
        environment = {**os.environ, **env} if env is not None else None
        self._process = subprocess.Popen(
            self.args, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
            stdin=subprocess.PIPE if stdin else subprocess.DEVNULL, env=environment, cwd=cwd,
            start_new_session=new_session)
        self._chunks: list[str] = []
        self._changed = threading.Condition()
        self._output_ended = False
        self._reader = threading.Thread(target=self._read, name=f"output of {self.pid}",
                                        daemon=True)
        self._reader.start()

    @property
    def pid(self) -> int:
        """The child's own process id."""
        return self._process.pid

    @property
    def returncode(self) -> int | None:
        """The exit status once reaped (negative: ended by that signal), else None."""
        return self._process.returncode

    def running(self) -> bool:
        """Whether the child has not ended yet (it is reaped as soon as it has)."""
        return self._process.poll() is None

    def _read(self) -> None:
        stream = self._process.stdout
        assert stream is not None
        for line in stream:
            with self._changed:
                self._chunks.append(line)
                self._changed.notify_all()
        stream.close()  # here, not from another thread while this one may be reading
        with self._changed:
            self._output_ended = True
            self._changed.notify_all()

    def output(self) -> str:
        """Everything the child has written so far (all of it once :meth:`wait` returned)."""
        with self._changed:
            return "".join(self._chunks)

    def _failure(self, what: str) -> AssertionError:
        tail = self.output()[-QUOTED_OUTPUT_CHARS:]
        return AssertionError(f"{what} ({' '.join(self.args)}); its output ends:\n{tail}")

    def wait_for(self, pattern: str | re.Pattern[str], timeout_s: float) -> re.Match[str]:
        """The first match of ``pattern`` (searched in the whole output so far, re.MULTILINE
        for a string) within ``timeout_s`` s; fails when the deadline passes or the output
        ends without one."""
        regex = re.compile(pattern, re.MULTILINE) if isinstance(pattern, str) else pattern
        deadline = time.monotonic() + timeout_s
        with self._changed:
            while True:
                found = regex.search("".join(self._chunks))
                if found is not None:
                    return found
                left_s = deadline - time.monotonic()
                if self._output_ended or left_s <= 0.0:
                    break
                self._changed.wait(left_s)
        ended = "its output ended" if self._output_ended else f"not within {timeout_s} s"
        raise self._failure(f"no {regex.pattern!r} in the output: {ended}")

    def write_line(self, text: str) -> None:
        """Write ``text`` and a newline to the child's stdin (started with ``stdin=True``)."""
        stream = self._process.stdin
        assert stream is not None, "started without stdin"
        stream.write(text + "\n")
        stream.flush()

    def ended_within(self, timeout_s: float) -> int | None:
        """The exit status if the child ends by itself within ``timeout_s`` s (its output then
        read whole), else None: it still runs."""
        try:
            status = self._process.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            return None
        self._reader.join(timeout=timeout_s)
        return status

    def wait(self, timeout_s: float) -> int:
        """Wait at most ``timeout_s`` s for the child to end by itself; its exit status, with
        all its output read. Fails (leaving the child to :meth:`close`) when it runs on."""
        status = self.ended_within(timeout_s)
        if status is None:
            raise self._failure(f"still running after {timeout_s} s")
        return status

    def send_signal(self, signum: int) -> None:
        """Send ``signum`` to the child's own PID, if it has not been reaped yet."""
        if self._process.returncode is None:
            self._process.send_signal(signum)

    def stop(self, signum: int = signal.SIGINT, grace_s: float = DEFAULT_GRACE_S) -> int:
        """End the child: ``signum`` by its own PID, then SIGKILL if it has not ended after
        ``grace_s`` s; always reaped, pipes closed. Its exit status (negative: the signal
        that ended it)."""
        try:
            if self._process.poll() is None:
                self._process.send_signal(signum)
                try:
                    self._process.wait(timeout=grace_s)
                except subprocess.TimeoutExpired:
                    self._process.kill()
            return self._process.wait()
        finally:
            self._close_pipes()

    def close(self) -> None:
        """End the child if it still runs (its ``stop_signal``, then SIGKILL after the grace
        period), reap it and close its pipes; safe to call more than once."""
        self.stop(self.stop_signal)

    def _close_pipes(self) -> None:
        """Close stdin; the reader closes stdout at its end, which a grandchild still holding
        the pipe may delay (the reader is a daemon thread: it never holds up the tests)."""
        if self._process.stdin is not None and not self._process.stdin.closed:
            try:
                self._process.stdin.close()
            except BrokenPipeError:
                pass
        self._reader.join(timeout=DEFAULT_GRACE_S)

    def __enter__(self) -> Program:
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 trace: TracebackType | None) -> None:
        self.close()


class Programs:
    """Several programs started one after the other and all ended together, the last started
    first (a context manager)."""

    def __init__(self) -> None:
        self.started: list[Program] = []

    def start(self, args: Sequence[str], *, env: Mapping[str, str] | None = None,
              cwd: Path | str | None = None, stdin: bool = False,
              stop_signal: int = signal.SIGINT, new_session: bool = False) -> Program:
        """Start one more program (the options of :class:`Program`)."""
        program = Program(args, env=env, cwd=cwd, stdin=stdin, stop_signal=stop_signal,
                          new_session=new_session)
        self.started.append(program)
        return program

    def first_to_end(self, timeout_s: float, poll_s: float = 0.05) -> Program:
        """The first started program found ended (reaped), checked every ``poll_s`` s; fails
        with every program's output when none has ended within ``timeout_s`` s."""
        deadline = time.monotonic() + timeout_s
        while True:
            for program in self.started:
                if not program.running():
                    return program
            if time.monotonic() >= deadline:
                break
            time.sleep(poll_s)
        outputs = "\n".join(f"{' '.join(p.args)}:\n{p.output()[-QUOTED_OUTPUT_CHARS:]}"
                            for p in self.started)
        raise AssertionError(f"none of the programs ended within {timeout_s} s:\n{outputs}")

    def close(self) -> None:
        """End, reap and close every program started, whatever fails on the way."""
        errors = []
        for program in reversed(self.started):
            try:
                program.close()
            except Exception as error:  # every program is ended before any error is raised
                errors.append(error)
        if errors:
            raise errors[0]

    def __enter__(self) -> Programs:
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 trace: TracebackType | None) -> None:
        self.close()

