"""The delay margin tau*(k) at a few gains k, from the sampled-data analysis, made once at start.

The margin governor (master/margin_governor.py) compares the measured round trip with this
table. Entries run from the configured k downwards by a constant ratio; the table stops at
the first k whose loop is stable for every delay the analysis searches (tau* = ``None``): a
lower k is not needed, that one is usable at any delay. Each entry costs one delay-margin
search per axis (up to a second or so), so a table is a few entries.

Changing k at run time: with Sh = St = 0 (the paper's handle and tool) every compensator is
linear in k (Ch1 = k N/D, Ct1 = Ch1/Ah2, Ch2 = -Ah1 Gh Ch1/Gt, Ct2 = -Ah1 Ah2^-1 Gh Ch1/Gt),
so the compensators at k are the configured ones with their inputs scaled by k/k0, and a
scale that changes slowly keeps the states continuous (no bump in the command):
:func:`gain_scalable` says whether a model is such a one.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from haptic.common.analysis.report import AnalysisSettings, axis_loop
from haptic.common.analysis.stability import delay_margin
from haptic.common.model.synthesis import SynthesisError
from haptic.common.model.teleop import TeleopModel, polynomial_degree, tf_coefficients


def gain_scalable(model: TeleopModel) -> bool:
    """Whether every compensator of ``model`` is linear in the Ch1 gain k (Sh = St = 0 on
    every axis), so that scaling the compensators' inputs by k/k0 gives the design at k."""
    for axis in model.axes:
        for compliance in (axis.handle_compliance_sh, axis.tool_compliance_st):
            num, _ = tf_coefficients(compliance)
            if polynomial_degree(num) >= 0:
                return False
    return True


def follow_gain(received_k: float, nominal_k: float, scalable: bool) -> float:
    """The slave's input scale k/k0 for the gain ``received_k`` the master says it uses
    (HandleState.gain_k): never above the slave's own ``nominal_k`` (a corrupt or mismatched
    value cannot raise the gain), 1 when not said (0) or when the design is not linear in k."""
    if not scalable or not 0.0 < received_k < float("inf"):
        return 1.0
    return min(received_k, nominal_k) / nominal_k


@dataclass(frozen=True)
class MarginEntry:
    """One gain: ``k`` and its round-trip delay margin (s; ``None``: no delay up to
    ``searched_up_to_s`` destabilises it; 0: unstable even without delay)."""

    k: float
    delay_margin_s: float | None


@dataclass(frozen=True)
class MarginTable:
    """Entries in decreasing k (the first is the configured k)."""

    entries: tuple[MarginEntry, ...]
    searched_up_to_s: float
    sample_period_s: float

    def margin_s(self, k: float) -> float:
        """tau*(k), s (inf when delay-independent): the margin of the smallest entry at or
        above ``k`` (for a k between entries, the higher entry's: conservative where tau*
        falls with k, as it does for the paper's loop)."""
        chosen = self.entries[0]
        for entry in self.entries:
            if entry.k >= k - 1e-12:
                chosen = entry
        margin = chosen.delay_margin_s
        return float("inf") if margin is None else margin

    def as_dict(self) -> dict[str, Any]:
        return {"k": [e.k for e in self.entries],
                "delay_margin_s": [e.delay_margin_s for e in self.entries],
                "searched_up_to_s": self.searched_up_to_s}

    def describe(self) -> str:
        """One line: k -> tau* for every entry."""
        parts = []
        for entry in self.entries:
            margin = entry.delay_margin_s
            text = "any delay" if margin is None else f"{margin * 1e3:.1f} ms"
            parts.append(f"k {entry.k:.3g}: {text}")
        return "tau*(k) sampled: " + ", ".join(parts)


def build_margin_table(model: TeleopModel, analysis: dict[str, Any], min_gain_k: float,
                       step_ratio: float, max_entries: int = 12) -> MarginTable:
    """tau*(k) of the sampled-data loop at Ts for k = k0, k0 r, k0 r^2, ... down to
    ``min_gain_k`` (always included), stopping at the first delay-independent k.
    ``analysis``: the validated ``[analysis]`` table (frequency and delay search bounds)."""
    settings = AnalysisSettings(
        max_frequency_rad_s=analysis["max_frequency_rad_s"],
        max_delay_s=analysis["max_delay_s"], max_gain_k=analysis["max_gain_k"],
        sample_period_s=model.sample_period_s)
    k0 = model.ch1_gain_k
    gains = [k0]
    while gains[-1] * step_ratio > min_gain_k and len(gains) < max_entries - 1:
        gains.append(gains[-1] * step_ratio)
    if gains[-1] > min_gain_k:
        gains.append(min_gain_k)
    entries = []
    for k in gains:
        margins: list[float | None] = []
        for axis in model.axes:
            try:
                loop = axis_loop(model, axis, k, settings)
            except SynthesisError:
                margins.append(0.0)
                continue
            margins.append(delay_margin(loop, settings.max_delay_s, settings.grid)
                           .delay_margin_s)
        finite = [m for m in margins if m is not None]
        entries.append(MarginEntry(float(k), min(finite) if finite else None))
        if not finite:
            break
    return MarginTable(tuple(entries), settings.max_delay_s, model.sample_period_s)


def table_from_pairs(pairs: list[tuple[float, float | None]], searched_up_to_s: float = 1.0,
                     sample_period_s: float = 0.00054) -> MarginTable:
    """A table from (k, tau* or None) pairs (tests; a table measured elsewhere)."""
    ordered = sorted(pairs, key=lambda pair: -pair[0])
    return MarginTable(tuple(MarginEntry(float(k), m) for k, m in ordered), searched_up_to_s,
                       sample_period_s)
