"""The ``[governor]`` table: the master's margin governor (master/margin_governor.py,
docs/governor.md)."""

from __future__ import annotations

from haptic.common.config.fields import Field, Schema

GOVERNOR_ACTIONS = ("lower_k", "tdpa")

GOVERNOR_SCHEMA: Schema = {
    "enabled": Field("bool", "Run the margin governor on the master (and haptic-sim run)."),
    "action": Field(
        "str", "Before the delay margin is reached: lower_k (lower Ch1's k smoothly, both "
        "sides) or tdpa (request the passivity mode; lower_k where this build has none).",
        choices=GOVERNOR_ACTIONS),
    "safety_factor": Field(
        "float", "A gain k is usable while the measured round trip is at most this fraction "
        "of its delay margin tau*(k).", minimum=0.0, exclusive_minimum=True, maximum=1.0),
    "urgent_factor": Field(
        "float", "A round trip above this fraction of tau*(k) is acted on at once (at least "
        "safety_factor).", minimum=0.0, exclusive_minimum=True, maximum=1.0),
    "confirm_s": Field(
        "float", "Between safety_factor and urgent_factor the round trip must stay there this "
        "long before the governor acts, s (0: at once; a scheduling blip is not the loop's "
        "delay).", minimum=0.0, maximum=1.0),
    "ramp_time_s": Field(
        "float", "k moves to a new value as a first-order lag that gets there (98 %) in this "
        "time, s.", minimum=0.0, exclusive_minimum=True, maximum=60.0),
    "hold_s": Field(
        "float", "The round trip that allows k back up is the peak over this window, s.",
        minimum=0.0, exclusive_minimum=True, maximum=600.0),
    "recover_after_s": Field(
        "float", "Raise k one table step after the peak round trip allowed it this long, s "
        "(0: never raise k again).", minimum=0.0, maximum=3600.0),
    "min_gain_k": Field(
        "float", "The lowest k the governor may use (the table's last entry).",
        minimum=0.0, exclusive_minimum=True),
    "step_ratio": Field(
        "float", "Ratio between neighbouring gains of the tau*(k) table.",
        minimum=0.1, maximum=0.95),
}
