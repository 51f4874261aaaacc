"""What the console scripts share before their heavy imports: a closed standard output (the
reader of a pipe gone, ``haptic-replay --json | head``) ends a program quietly.

Standard library only: importing this module costs nothing a ``--help`` would notice.
"""

from __future__ import annotations

import functools
import os
import signal
import sys
from collections.abc import Callable
from typing import ParamSpec

P = ParamSpec("P")

#: The exit status of a program whose output pipe closed: what a shell reports for a process
#: ended by SIGPIPE (128 + 13), as Python's documentation suggests (signal, "Note on SIGPIPE").
BROKEN_PIPE_EXIT_STATUS = 128 + signal.SIGPIPE


def quiet_on_closed_stdout(main: Callable[P, int]) -> Callable[P, int]:
    """Wrap a console script's ``main``: when its standard output is a pipe whose reader has
    gone, return :data:`BROKEN_PIPE_EXIT_STATUS` without a traceback. The rest of the output
    goes to /dev/null, so the interpreter's own flush at exit does not fail again. The
    output is flushed before ``main``'s status is returned, inside the guard."""

    @functools.wraps(main)
    def guarded(*args: P.args, **kwargs: P.kwargs) -> int:
        try:
            status = main(*args, **kwargs)
            sys.stdout.flush()
            return status
        except BrokenPipeError:
            _stdout_to_devnull()
            return BROKEN_PIPE_EXIT_STATUS

    return guarded


def _stdout_to_devnull() -> None:
    """Point file descriptor 1 (when sys.stdout has one) at /dev/null."""
    try:
        descriptor = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):  # a replaced stream (tests) has none
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, descriptor)
    os.close(devnull)


def script_description(doc: str) -> str:
    """A console script's ``--help`` description from its module docstring: the first
    paragraph as one line, whole; reST literals as plain text; without the leading
    ``haptic-x [ARGS]:`` label; starting with a capital letter and ending with a full stop."""
    paragraph = " ".join(doc.strip().split("\n\n")[0].split())
    text = paragraph.replace("``", "").replace("`", "")
    label, colon, rest = text.partition(": ")
    if colon and label.split()[0].startswith("haptic-"):
        text = rest
    text = text[:1].upper() + text[1:]
    return text if text.endswith((".", "!", "?")) else text + "."
