"""The ``[lockstep]`` table: the reproduction's operators and the assumed rig loop delay."""

from __future__ import annotations

from haptic.common.config.fields import Field, Schema
from haptic.common.config.operator_spec import check_operator_spec

LOCKSTEP_SCHEMA: Schema = {
    "gain_experiment_loop_delay_s": Field(
        "float", "Round-trip loop delay assumed for the paper's rig in the Ch1 gain "
        "experiment (k = 3, 13, 19), s; docs/lockstep.md gives the reason.", minimum=0.0,
        maximum=1.0),
    "constant_rate_operator": Field("str", "Operator of the constant-rate cut (paper 4.1).",
                                    check=check_operator_spec),
    "variable_rate_operator": Field("str", "Operator of the variable-rate cut (paper 4.2).",
                                    check=check_operator_spec),
    "gain_operator": Field("str", "Operator of the gain experiment (paper 4.3).",
                           check=check_operator_spec),
    "seed": Field("int", "Seed of every random source of a lockstep run.", minimum=0),
}
