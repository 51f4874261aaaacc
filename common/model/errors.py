"""The one error a model's parameters raise: :class:`ConfigError`, naming the configuration key.

It lives at the bottom layer so the models (common/model/) can name the key a bad parameter
came from without importing the configuration reader above them;
:mod:`haptic.common.config` re-exports it, and every program turns it into one line and
exit status 2.
"""

from __future__ import annotations


class ConfigError(ValueError):
    """An invalid configuration; ``key`` is the dotted name of the offending key."""

    def __init__(self, key: str, message: str) -> None:
        super().__init__(f"{key}: {message}" if key else message)
        self.key = key
