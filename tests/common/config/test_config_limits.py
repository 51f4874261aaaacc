"""The configuration reader at its edges (common/config/loader.py): every value kind's checks
one at a time, each bound at its value, strings at their length and control characters, a
binary file, the TOML it writes back (keys quoted, non-finite numbers, tables without keys of
their own), and the one line and exit status 2 of a configuration error."""

from __future__ import annotations

import dataclasses
import math
import tomllib
from pathlib import Path

import pytest

from haptic.common.config.loader import (
    CONFIG_ERROR_EXIT_STATUS,
    MAX_STRING_LENGTH,
    Field,
    exit_on_config_error,
    load_config,
    read_config_text,
    to_toml,
    validate_table,
)
from haptic.common.model.errors import ConfigError

SCHEMA = {
    "count": Field("int", "a count", minimum=1, maximum=3),
    "gain": Field("float", "a gain", minimum=0.0, exclusive_minimum=True),
    "name": Field("str", "a name"),
    "poles": Field("float_list", "a list", minimum=-1.0, maximum=1.0),
    "ratio": Field("matrix2", "a matrix"),
}
DEFAULTS = {"count": 2, "gain": 1.0, "name": "a", "poles": [0.0], "ratio": [[1.0, 0.0],
                                                                             [0.0, 1.0]]}


def check(key: str, value: object) -> object:
    return validate_table({key: value}, SCHEMA, DEFAULTS)[key]


def refused(key: str, value: object, text: str) -> None:
    with pytest.raises(ConfigError, match=text) as error:
        check(key, value)
    assert error.value.key == key


def test_the_exit_status_the_string_limit_and_frozen_fields() -> None:
    assert (CONFIG_ERROR_EXIT_STATUS, MAX_STRING_LENGTH) == (2, 1024)
    with pytest.raises(dataclasses.FrozenInstanceError):
        SCHEMA["count"].kind = "float"  # type: ignore[misc]


def test_an_integer_key_takes_integers_only_within_its_bounds() -> None:
    assert check("count", 1) == 1 and check("count", 3) == 3
    refused("count", True, "must be an integer")  # a bool is an int to Python, not here
    refused("count", 2.0, "must be an integer")
    refused("count", 0, "must be >= 1")
    refused("count", 4, "must be <= 3")


def test_an_exclusive_minimum_refuses_the_minimum_itself() -> None:
    refused("gain", 0.0, r"must be > 0 \(got 0\)")
    assert check("gain", 5e-324) == 5e-324


def test_a_string_at_the_length_limit_and_without_control_characters() -> None:
    assert check("name", "x" * MAX_STRING_LENGTH) == "x" * MAX_STRING_LENGTH
    refused("name", "x" * (MAX_STRING_LENGTH + 1), "at most 1024 characters")
    for bad in ("a\x00b", "a\x1fb", "a\x7fb"):
        refused("name", bad, "control characters")
    assert check("name", "caf\u00e9 \x80 ~") == "caf\u00e9 \x80 ~"  # above DEL: not controls


def test_a_list_must_be_a_non_empty_list_of_finite_numbers_each_within_bounds() -> None:
    assert check("poles", [-1, 1.0]) == [-1.0, 1.0]
    for bad in ((0.5, 0.5), [], [0.5, math.nan], [0.5, "0.5"], [0.5, True]):
        refused("poles", bad, "non-empty list of finite numbers")
    refused("poles", [0.5, 1.5], "must be <= 1")
    refused("poles", [-1.5, 0.5], "must be >= -1")


def test_a_matrix_must_be_two_lists_of_two_finite_numbers() -> None:
    assert check("ratio", [[1, 0], [0, 2.5]]) == [[1.0, 0.0], [0.0, 2.5]]
    for bad in (([1, 0], [0, 1]), [[1, 0], [0, 1], [0, 0]], [[1, 0], (0, 1)],
                [[1, 0, 0], [0, 1, 0]], [[math.nan, 0], [0, 1]], [[1, 0], [0, math.inf]]):
        refused("ratio", bad, "2x2 matrix of finite numbers")


def test_a_binary_file_is_a_configuration_error_naming_it(tmp_path: Path) -> None:
    path = tmp_path / "config.toml"
    path.write_bytes(b"model = 1\n\xff\xfe")
    with pytest.raises(ConfigError, match=r"is not UTF-8 text \(byte 10\)"):
        read_config_text(path, "config file")
    with pytest.raises(ConfigError, match="cannot read config file"):
        read_config_text(tmp_path / "missing.toml", "config file")


def test_written_toml_quotes_keys_that_need_it_and_keeps_their_characters() -> None:
    text = to_toml({"plain_key-1": 1, "a b": 2, "caf\u00e9": "\u00e9t\u00e9", "": True})
    assert text == ('plain_key-1 = 1\n"a b" = 2\n"caf\u00e9" = "\u00e9t\u00e9"\n'
                    '"" = true\n')
    assert tomllib.loads(text) == {"plain_key-1": 1, "a b": 2, "caf\u00e9": "\u00e9t\u00e9",
                                   "": True}


def test_written_toml_spells_non_finite_numbers() -> None:
    text = to_toml({"a": math.inf, "b": -math.inf, "c": math.nan, "d": -0.5})
    assert text == "a = inf\nb = -inf\nc = nan\nd = -0.5\n"
    values = tomllib.loads(text)
    assert values["a"] == math.inf and values["b"] == -math.inf and math.isnan(values["c"])


def test_a_table_gets_a_header_only_where_it_has_keys_of_its_own() -> None:
    text = to_toml({"top": 1, "a": {"b": {"c": 2}}})
    assert text == "top = 1\n\n[a.b]\nc = 2\n"
    assert tomllib.loads(text) == {"top": 1, "a": {"b": {"c": 2}}}
    assert load_config() == tomllib.loads(to_toml(load_config()))  # the shipped set


def test_a_configuration_error_is_one_line_and_exit_status_2(capsys) -> None:
    with pytest.raises(SystemExit) as exit_info, exit_on_config_error():
        raise ConfigError("master.safety.force_limit_N", "must be > 0 (got -1)")
    assert exit_info.value.code == 2
    assert capsys.readouterr().err == (
        "config error: master.safety.force_limit_N: must be > 0 (got -1)\n")
    with exit_on_config_error():  # nothing raised: nothing said
        pass
    assert capsys.readouterr().err == ""
