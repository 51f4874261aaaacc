"""The ``[slave]`` table of the main configuration (appended to the shared schema)."""

from __future__ import annotations

import re

from haptic.common.config.fields import Field, Schema


def device_form_problem(value: str) -> str | None:
    """What is wrong with ``value`` as a Warp device name (None: nothing)."""
    if value in ("auto", "cpu", "cuda") or re.fullmatch(r"cuda:(0|[1-9][0-9]*)", value):
        return None
    return f"must be auto, cpu, cuda or cuda:N (got {value!r})"


#: [slave.safety]: the slave's bounds on received handle messages (slave_sim/input_guard.py).
SAFETY_SCHEMA: Schema = {
    "force_limit_N": Field(
        "float", "The received handle force saturates here per axis, N.", minimum=0.0,
        exclusive_minimum=True),
    "force_trip_N": Field(
        "float", "A received handle force beyond this on an axis is a fault, N.", minimum=0.0,
        exclusive_minimum=True),
    "force_rate_limit_N_per_s": Field(
        "float", "The received handle force changes at most this fast per axis, N/s.",
        minimum=0.0, exclusive_minimum=True),
    "position_min_m": Field("float_list", "Lowest plausible handle position (x, y), m.",
                            check=lambda v: None if len(v) == 2 else "must have 2 values"),
    "position_max_m": Field("float_list", "Highest plausible handle position (x, y), m.",
                            check=lambda v: None if len(v) == 2 else "must have 2 values"),
    "velocity_trip_m_per_s": Field(
        "float", "A handle position that moved faster than this between two messages is a "
        "fault, m/s.", minimum=0.0, exclusive_minimum=True),
    "jump_margin_m": Field(
        "float", "Allowance on top of the speed bound for a position jump, m.", minimum=0.0),
    "clear_after_messages": Field(
        "int", "Plausible messages in a row that clear an input fault.", minimum=1),
    "jitter_allowance_s": Field(
        "float", "How much earlier than usual (delay shorter than usual) a message may arrive "
        "and its send-time difference still count in full in the jump and rate bounds, s.",
        minimum=0.0, maximum=1.0),
}


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
                    check=device_form_problem),
    "safety": SAFETY_SCHEMA,
    "pacing": {
        "follow_master_samples": Field(
            "bool", "One node step per master sample, counted by sequence number (a tick "
            "without a new sample waits, one after a gap catches up; slave_sim/pacing.py); "
            "false: one node step per tick.",
        ),
        "max_steps_per_tick": Field(
            "int", "The node steps one tick takes to catch up with the master's samples while "
            "the backlog is within max_backlog_samples.",
            minimum=1, maximum=16,
        ),
        "max_backlog_samples": Field(
            "int", "The most master samples owed to later ticks when one tick cannot take them "
            "all (each delays the tool by Ts); beyond, the tick takes them at once (a longer "
            "tick, counted), never giving them up.",
            minimum=0, maximum=1024,
        ),
    },
    "phase_lock": {
        "enabled": Field(
            "bool", "Keep the slave's ticks a set lag after the master's messages arrive "
            "(common/wire/phase_lock.py); false: the loop ticks free-running.",
        ),
        "margin_s": Field(
            "float", "The slave's spin before its tick starts this long after the master's "
            "message arrives, s: the tick comes runner.spin_s + margin_s after the arrival.",
            minimum=0.0, maximum=0.01,
        ),
    },
}
