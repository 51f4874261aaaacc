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
import math
import sys
import tomllib
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

from haptic.common.model.errors import ConfigError

CONFIG_ERROR_EXIT_STATUS = 2
#: The longest string value, characters (names, interfaces and paths: a path's own limits,
#: 4096 bytes and 255 per component on Linux, are the operating system's to report).
MAX_STRING_LENGTH = 1024


@dataclass(frozen=True)
class Field:
    """One configuration key.

    ``kind`` is one of ``float``, ``int``, ``bool``, ``str``, ``float_list`` (a non-empty
    list of finite numbers), ``matrix2`` (a 2x2 list of lists of finite numbers).
    ``minimum``/``maximum`` bound numbers (``float``, ``int``) and every element of lists;
    ``exclusive_minimum`` makes the lower bound strict. ``choices`` restricts ``str`` values.
    ``check`` is an extra validator returning an error message or ``None``.
    ``together`` names sibling keys that a file must set whenever it sets this one (a
    numerator and its denominator).
    """

    kind: str
    doc: str
    minimum: float | None = None
    maximum: float | None = None
    exclusive_minimum: bool = False
    choices: tuple[str, ...] | None = None
    check: Callable[[Any], str | None] | None = None
    together: tuple[str, ...] = ()


Schema = Mapping[str, "Field | Schema"]


def _finite_number(value: Any) -> bool:
    return (
        isinstance(value, int | float)
        and not isinstance(value, bool)
        and math.isfinite(float(value))
    )


def _check_bounds(key: str, field: Field, number: float) -> None:
    if field.minimum is not None:
        if field.exclusive_minimum and not number > field.minimum:
            raise ConfigError(key, f"must be > {field.minimum:g} (got {number:g})")
        if not field.exclusive_minimum and not number >= field.minimum:
            raise ConfigError(key, f"must be >= {field.minimum:g} (got {number:g})")
    if field.maximum is not None and not number <= field.maximum:
        raise ConfigError(key, f"must be <= {field.maximum:g} (got {number:g})")


def _validate_field(key: str, field: Field, value: Any) -> Any:
    kind = field.kind
    if kind == "float":
        if not _finite_number(value):
            raise ConfigError(key, f"must be a finite number (got {value!r})")
        result: Any = float(value)
        _check_bounds(key, field, result)
    elif kind == "int":
        if not isinstance(value, int) or isinstance(value, bool):
            raise ConfigError(key, f"must be an integer (got {value!r})")
        result = value
        _check_bounds(key, field, result)
    elif kind == "bool":
        if not isinstance(value, bool):
            raise ConfigError(key, f"must be true or false (got {value!r})")
        result = value
    elif kind == "str":
        if not isinstance(value, str):
            raise ConfigError(key, f"must be a string (got {value!r})")
        if len(value) > MAX_STRING_LENGTH:
            raise ConfigError(key, f"must be at most {MAX_STRING_LENGTH} characters "
                              f"(got {len(value)})")
        if any(ord(c) < 0x20 or ord(c) == 0x7F for c in value):
            raise ConfigError(key, f"must not hold control characters (got {value!r})")
        if field.choices is not None and value not in field.choices:
            raise ConfigError(key, f"must be one of {', '.join(field.choices)} (got {value!r})")
        result = value
    elif kind == "float_list":
        if not isinstance(value, list) or not value or not all(map(_finite_number, value)):
            raise ConfigError(key, f"must be a non-empty list of finite numbers (got {value!r})")
        result = [float(v) for v in value]
        for element in result:
            _check_bounds(key, field, element)
    elif kind == "matrix2":
        if (
            not isinstance(value, list)
            or len(value) != 2
            or not all(isinstance(row, list) and len(row) == 2 for row in value)
            or not all(_finite_number(v) for row in value for v in row)
        ):
            raise ConfigError(key, f"must be a 2x2 matrix of finite numbers (got {value!r})")
        result = [[float(v) for v in row] for row in value]
    else:  # pragma: no cover - a schema bug, not user input
        raise AssertionError(f"unknown field kind {kind!r} for {key}")
    if field.check is not None:
        problem = field.check(result)
        if problem:
            raise ConfigError(key, problem)
    return result


def _join(prefix: str, name: str) -> str:
    return f"{prefix}.{name}" if prefix else name


def validate_table(
    table: Mapping[str, Any], schema: Schema, defaults: Mapping[str, Any], prefix: str = ""
) -> dict[str, Any]:
    """Validate ``table`` against ``schema``; sub-tables missing from ``table`` come from
    ``defaults`` (already validated). Returns a new plain dict."""
    if not isinstance(table, Mapping):
        raise ConfigError(prefix, f"must be a table (got {table!r})")
    for name in table:
        if name not in schema:
            raise ConfigError(_join(prefix, name), "unknown key")
    result: dict[str, Any] = {}
    for name, spec in schema.items():
        key = _join(prefix, name)
        if isinstance(spec, Field):
            if name in table:
                for partner in spec.together:
                    if partner not in table:
                        raise ConfigError(_join(prefix, partner),
                                          f"missing key (set together with {key})")
                result[name] = _validate_field(key, spec, table[name])
            elif name in defaults:
                result[name] = defaults[name]
            else:
                raise ConfigError(key, "missing key")
        elif name in table:
            result[name] = validate_table(table[name], spec, defaults.get(name, {}), key)
        elif name in defaults:
            result[name] = defaults[name]
        else:
            raise ConfigError(key, "missing table")
    return result


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
    from haptic.common.config.schema import SCHEMA, check_across_keys

    defaults = validate_table(parse_toml(default_config_text(), "defaults"), SCHEMA, {})
    if path is None:
        return defaults
    text = read_config_text(path, "config file")
    config = validate_table(parse_toml(text, str(path)), SCHEMA, defaults)
    check_across_keys(config)
    return config


def override(config: dict[str, Any], dotted_key: str, value: Any) -> dict[str, Any]:
    """Return a copy of ``config`` with one key replaced (a CLI flag), validated."""
    from haptic.common.config.schema import SCHEMA

    parts = dotted_key.split(".")
    spec: Any = SCHEMA
    for part in parts:
        if not isinstance(spec, Mapping) or part not in spec:
            raise ConfigError(dotted_key, "unknown key")
        spec = spec[part]
    if not isinstance(spec, Field):
        raise ConfigError(dotted_key, "is a table, not a key")
    checked = _validate_field(dotted_key, spec, value)
    result = _deep_copy(config)
    node = result
    for part in parts[:-1]:
        node = node[part]
    node[parts[-1]] = checked
    from haptic.common.config.schema import check_across_keys

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
