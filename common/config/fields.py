"""The configuration's schema vocabulary and its validation: a :class:`Field` per key, a
:data:`Schema` as nested tables of them, and :func:`validate_table`, which checks a parsed
table against a schema over validated defaults. The schema modules and the loader both import
this module, which imports neither of them."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from haptic.common.model.errors import ConfigError

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


def validate_field(key: str, field: Field, value: Any) -> Any:
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
                result[name] = validate_field(key, spec, table[name])
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
