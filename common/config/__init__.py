"""Configuration: the TOML files every program reads, merged key by key over the shipped
defaults (the paper's values) and validated against one schema.

The schema tables are plain data (``schema``, ``master_schema``, ``slave_schema``,
``lockstep_schema``, ``operator_spec``): reading a configuration imports no backend, no
CAN stack and no package above ``haptic.common`` (tests/common/test_layers.py checks it).
The public API is re-exported here from :mod:`haptic.common.config.loader`.
"""

from haptic.common.config.loader import (
    CONFIG_ERROR_EXIT_STATUS,
    ConfigError,
    Field,
    Schema,
    default_config_text,
    exit_on_config_error,
    load_config,
    override,
    parse_toml,
    read_config_text,
    to_toml,
    validate_table,
)

__all__ = [
    "CONFIG_ERROR_EXIT_STATUS",
    "ConfigError",
    "Field",
    "Schema",
    "default_config_text",
    "exit_on_config_error",
    "load_config",
    "override",
    "parse_toml",
    "read_config_text",
    "to_toml",
    "validate_table",
]
