"""Clean failures: the errors a program cannot run past, as one line and a documented status.

Exit statuses shared by every program (docs/programs.md):

- 2 (:data:`haptic.common.config.CONFIG_ERROR_EXIT_STATUS`): a configuration error, including a
  config file that cannot be read or decoded;
- :data:`LINK_ERROR_EXIT_STATUS` (4): the link cannot be opened: a listen port in use, a
  router or peer that cannot be reached in client mode, a Zenoh configuration Zenoh refuses,
  an HTTP port in use (``haptic-view``), a session key that cannot be read.

Zenoh's messages carry the Rust source positions (``at /root/.cargo/...rs:61.``) and may span
lines; :func:`~haptic.common.wire.errors.one_line` keeps the part a user can act on.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator
from contextlib import contextmanager

from haptic.common.wire.errors import LinkOpenError, one_line

LINK_ERROR_EXIT_STATUS = 4

@contextmanager
def exit_on_link_error(program: str) -> Iterator[None]:
    """Turn a :class:`LinkOpenError` into ``PROGRAM: link error: ...`` on stderr and exit
    status :data:`LINK_ERROR_EXIT_STATUS`."""
    try:
        yield
    except LinkOpenError as error:
        print(f"{program}: link error: {one_line(error)}", file=sys.stderr, flush=True)
        raise SystemExit(LINK_ERROR_EXIT_STATUS) from None
