"""TOML configuration: load, merge over the shipped defaults, validate against the schema.

Rules, the same for every program:

- The shipped defaults (``defaults/paper.toml``) are the paper's values.
- A user file is merged over the defaults key by key: it may set any subset of the keys of
  any table, and every key it leaves out keeps its default. Keys that only mean something
  together (a polynomial's numerator and denominator) are set together or not at all.
- Unknown tables or keys, wrong types and out-of-range values are errors.
- Every error is a :class:`ConfigError` whose message names the dotted key; programs print it
  on one line and exit with status 2 (see :func:`exit_on_config_error`).
"""

from __future__ import annotations

import json
import sys
import tomllib
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from importlib import resources
from pathlib import Path
from typing import Any

from haptic.common.config.fields import (
    MAX_STRING_LENGTH,
    Field,
    Schema,
    validate_field,
    validate_table,
)
from haptic.common.config.schema import SCHEMA, check_across_keys
from haptic.common.model.errors import ConfigError

__all__ = ["CONFIG_ERROR_EXIT_STATUS", "MAX_STRING_LENGTH", "ConfigError", "Field", "Schema",
           "default_config_text", "exit_on_config_error", "load_config", "override",
           "parse_toml", "read_config_text", "to_toml", "validate_table"]

CONFIG_ERROR_EXIT_STATUS = 2
def default_config_text() -> str:
    """The shipped defaults (the paper's values) as TOML text."""
    return resources.files("haptic.common.config").joinpath("defaults/paper.toml").read_text()


def parse_toml(text: str, source: str) -> dict[str, Any]:
    """Parse TOML, turning syntax errors into a :class:`ConfigError`."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise ConfigError("", f"{source}: not valid TOML: {error}") from None


def read_config_text(path: str | Path, what: str) -> str:
    """The UTF-8 text of a configuration file; an unreadable or undecodable (binary) file is a
    :class:`ConfigError` naming it."""
    try:
        return Path(path).read_bytes().decode("utf-8")
    except OSError as error:
        raise ConfigError("", f"cannot read {what} {path}: {error.strerror}") from None
    except UnicodeDecodeError as error:
        raise ConfigError("", f"{what} {path} is not UTF-8 text (byte {error.start}): "
                          "not a TOML file") from None


def load_config(path: str | Path | None = None) -> dict[str, Any]:
    """Load the configuration: the shipped defaults, with ``path`` (if given) on top.

    Raises :class:`ConfigError` for an unreadable file or an invalid key or value.
    """
    defaults = validate_table(parse_toml(default_config_text(), "defaults"), SCHEMA, {})
    if path is None:
        return defaults
    text = read_config_text(path, "config file")
    config = validate_table(parse_toml(text, str(path)), SCHEMA, defaults)
    check_across_keys(config)
    return config


def override(config: dict[str, Any], dotted_key: str, value: Any) -> dict[str, Any]:
    """Return a copy of ``config`` with one key replaced (a CLI flag), validated."""
    parts = dotted_key.split(".")
    spec: Any = SCHEMA
    for part in parts:
        if not isinstance(spec, Mapping) or part not in spec:
            raise ConfigError(dotted_key, "unknown key")
        spec = spec[part]
    if not isinstance(spec, Field):
        raise ConfigError(dotted_key, "is a table, not a key")
    checked = validate_field(dotted_key, spec, value)
    result = _deep_copy(config)
    node = result
    for part in parts[:-1]:
        node = node[part]
    node[parts[-1]] = checked
    check_across_keys(result)
    return result


def _toml_key(name: str) -> str:
    return name if name and all(c.isascii() and (c.isalnum() or c in "_-") for c in name) \
        else json.dumps(name, ensure_ascii=False)


def _toml_value(key: str, value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return repr(value)  # Python's inf, -inf and nan are TOML's spellings too
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)  # a JSON string is a TOML basic string
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(key, item) for item in value) + "]"
    raise ConfigError(key, f"cannot be written as TOML (a {type(value).__name__})")


def to_toml(config: Mapping[str, Any]) -> str:
    """A configuration (nested tables of the schema's value kinds) as TOML text that
    :func:`load_config` reads back to the same values: every table with all its keys, so
    another process can be given exactly this run's configuration."""
    lines: list[str] = []

    def table(node: Mapping[str, Any], path: list[str]) -> None:
        plain = [(k, v) for k, v in node.items() if not isinstance(v, Mapping)]
        if path and plain:
            lines.extend(["", "[" + ".".join(map(_toml_key, path)) + "]"])
        for name, value in plain:
            lines.append(f"{_toml_key(name)} = {_toml_value('.'.join([*path, name]), value)}")
        for name, value in node.items():
            if isinstance(value, Mapping):
                table(value, [*path, name])

    table(config, [])
    return "\n".join(lines).lstrip("\n") + "\n"


def _deep_copy(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _deep_copy(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_deep_copy(v) for v in value]
    return value


@contextmanager
def exit_on_config_error() -> Iterator[None]:
    """Turn a :class:`ConfigError` into one line on stderr and exit status 2."""
    try:
        yield
    except ConfigError as error:
        print(f"config error: {error}", file=sys.stderr)
        raise SystemExit(CONFIG_ERROR_EXIT_STATUS) from None
