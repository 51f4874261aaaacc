"""The ``[slave]`` table of the main configuration (appended to the shared schema)."""

from __future__ import annotations

import re

from haptic.common.config.loader import Field, Schema


def _device(value: str) -> str | None:
    if value in ("auto", "cpu", "cuda") or re.fullmatch(r"cuda:\d+", value):
        return None
    return f"must be auto, cpu, cuda or cuda:N (got {value!r})"


SLAVE_SCHEMA: Schema = {
    "scenario": Field(
        "str", "Slave scenario: a shipped name (constant-rate, variable-rate, arbitrary) or the "
        "path of a scenario TOML file.",
    ),
    "environment": Field(
        "str", "Tool environment: scenario (the scenario's own), clay (Warp height field) or "
        "linear (ft = Tt yt with model.*.environment_impedance_tt).",
        choices=("scenario", "clay", "linear"),
    ),
    "clay_impl": Field("str", "Clay step implementation: warp (kernels) or numpy (reference).",
                       choices=("warp", "numpy")),
    "device": Field("str", "Warp device: auto (cuda when present, else cpu), cpu, cuda, cuda:N.",
                    check=_device),
    "phase_lock": {
        "enabled": Field(
            "bool", "Keep the slave's ticks a set lag after the master's messages arrive "
            "(common/phase_lock.py); false: the loop ticks free-running.",
        ),
        "margin_s": Field(
            "float", "The slave's spin before its tick starts this long after the master's "
            "message arrives, s: the tick comes runner.spin_s + margin_s after the arrival.",
            minimum=0.0, maximum=0.01,
        ),
    },
}
