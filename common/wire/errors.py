"""The link's one error, :class:`LinkOpenError`, and :func:`one_line`, which makes Zenoh's
multi-line messages (with Rust source positions) one line a user can act on.
:mod:`haptic.common.runtime.failures` turns the error into exit status 4.
"""

from __future__ import annotations

import re

_RUST_POSITION = re.compile(r"\s*at\s+\S+\.rs:\d+\.?")
_MAX_LINE_CHARACTERS = 300


class LinkOpenError(RuntimeError):
    """The link (a Zenoh session, a port, a key file) could not be opened; the message is one
    line."""


def one_line(error: BaseException | str, limit: int = _MAX_LINE_CHARACTERS) -> str:
    """``error``'s text on one line, without Rust source positions, at most ``limit`` chars."""
    text = _RUST_POSITION.sub("", str(error))
    text = " ".join(text.split())
    return text if len(text) <= limit else text[: limit - 3] + "..."
