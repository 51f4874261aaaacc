"""Stability of the whole loop cutting clay, per block: the clay linearised about steady
cutting (common/model/clay_contact.py) as the environment impedance Tt of each axis, analysed
like any other Tt (docs/clay.md, "Choosing k for a workpiece").

For each block of damping B: is the loop stable at the chosen k and round-trip delay, its
delay margin, the largest stable k at that delay and the largest k stable for every delay.
The block with the smallest bound limits the workpiece; blocks without clay (B = 0) leave the
operator's loop alone and are not analysed.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

from haptic.common.analysis.report import AnalysisSettings, analyse
from haptic.common.model.clay_contact import (
    COUPLING_DAMPING_N_S_PER_M,
    COUPLING_STIFFNESS_N_PER_M,
    clay_impedance,
)
from haptic.common.model.teleop import TeleopModel


@dataclass(frozen=True)
class BlockStability:
    """The loop cutting one block (worst axis): verdict at (k, delay), margins and bounds."""

    block: str
    damping_N_s_per_m: float
    stable: bool
    delay_margin_s: float | None
    k_max: float | None
    k_max_delay_independent: float | None


def clay_model(model: TeleopModel, damping_N_s_per_m: float,
               stiffness_N_per_m: float = COUPLING_STIFFNESS_N_PER_M,
               coupling_damping_N_s_per_m: float = COUPLING_DAMPING_N_S_PER_M) -> TeleopModel:
    """``model`` with every axis's Tt the clay of damping ``damping_N_s_per_m`` linearised
    about steady cutting."""
    num, den = clay_impedance(damping_N_s_per_m, stiffness_N_per_m, coupling_damping_N_s_per_m)
    axes = tuple(axis.with_environment(num, den) for axis in model.axes)
    return TeleopModel(model.sample_period_s, model.ch1_gain_k, model.ch1_num, model.ch1_den,
                       axes)


def clay_block_stability(model: TeleopModel, blocks: list[tuple[str, float]], k: float,
                         delay_s: float, settings: AnalysisSettings,
                         stiffness_N_per_m: float = COUPLING_STIFFNESS_N_PER_M,
                         coupling_damping_N_s_per_m: float = COUPLING_DAMPING_N_S_PER_M
                         ) -> list[BlockStability]:
    """One :class:`BlockStability` per ``(name, damping N s/m)`` block with clay."""
    out = []
    for name, damping in blocks:
        if damping <= 0.0:
            continue
        analysis = analyse(clay_model(model, damping, stiffness_N_per_m,
                                      coupling_damping_N_s_per_m), k, delay_s, settings)
        out.append(BlockStability(name, float(damping), analysis.stable,
                                  analysis.delay_margin_s, analysis.k_max,
                                  analysis.k_max_delay_independent))
    return out


def workpiece_bounds(blocks: list[BlockStability]) -> dict[str, Any]:
    """The workpiece's limits: the smallest delay margin and k bounds over its blocks (None
    where a block has no bound: stable for every delay, or no stable k)."""
    def smallest(values: list[float | None], none_is_unbounded: bool) -> float | None:
        finite = [v for v in values if v is not None]
        if none_is_unbounded:
            return min(finite) if finite else None
        return None if len(finite) < len(values) else min(finite)

    return {
        "stable": all(b.stable for b in blocks),
        "delay_margin_s": smallest([b.delay_margin_s for b in blocks], True),
        "k_max": smallest([b.k_max for b in blocks], False),
        "k_max_delay_independent": smallest([b.k_max_delay_independent for b in blocks], False),
    }


def to_json(blocks: list[BlockStability]) -> list[dict[str, Any]]:
    """Plain dicts, one per block."""
    return [asdict(block) for block in blocks]


__all__ = ["BlockStability", "clay_block_stability", "clay_model", "to_json",
           "workpiece_bounds"]
