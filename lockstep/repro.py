"""Reproduction of the paper's section 4 with the lockstep simulator (docs/lockstep.md).

Three experiments, each one lockstep run (several lanes for the gain experiment):

- 4.1 constant cutting rate: constant-rate workpiece (clay B = 100 N s/m from x = 2 to
  12 cm), k = 1, no loop delay, the regulating operator holding 3.6 N;
- 4.2 variable cutting rate: staircase workpiece p = 100 .. 20 N s/m, the operator
  regulating 3 N, so v = 3 N / p on each step;
- 4.3 Ch1 gain: k = 3, 13, 19 with the environment of the paper's stability analysis
  (Tt of eq 33, the linear environment) on the arbitrary scenario, a steady 3 N push and the
  assumed round-trip loop delay ``[lockstep] gain_experiment_loop_delay_s``.

:func:`reproduce` returns the table rows (paper, ours, tolerance) and the traces;
:func:`write_report` writes report.md and the PNG figures.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from haptic.common.analysis.report import AnalysisSettings, analyse
from haptic.common.config.scenario import load_scenario
from haptic.common.model.teleop import TeleopModel, model_from_config
from haptic.common.records.cutting import cutting_steadiness
from haptic.lockstep.simulator import TRANSPARENT_SAFETY, LockstepSimulator
from haptic.lockstep.sweep import analytic_margin_s
from haptic.master.simulated_rig.operator import parse_operator_spec

GAINS = (3.0, 13.0, 19.0)
#: Force above which the tool counts as in contact with the clay, N.
CONTACT_FORCE_N = 0.05
VARIABLE_STEPS = (("p100", 100.0), ("p80", 80.0), ("p60", 60.0), ("p40", 40.0),
                  ("p20", 20.0))


#: What a row's number is: a prediction of the model (counts as agreement when within its
#: tolerance), a figure the fit of a parameter was made to (not agreement: it agrees by
#: construction or nearly), or the fitted parameter itself (not judged).
BASES = ("predicted", "fitted", "parameter")


@dataclass(frozen=True)
class Row:
    """One line of the table: the paper's number, ours, the tolerance test and the row's
    basis (:data:`BASES`); ``fitted_by`` names the fitted parameter a non-predicted row
    comes from. ``within_tolerance`` is None for a parameter (nothing to test)."""

    name: str
    unit: str
    paper: float | None
    ours: float
    tolerance: str
    within_tolerance: bool | None
    basis: str = "predicted"
    fitted_by: str | None = None

    @property
    def counts_as_agreement(self) -> bool:
        """A predicted row within its tolerance: the only kind that confirms the model."""
        return self.basis == "predicted" and bool(self.within_tolerance)

    def as_dict(self) -> dict[str, Any]:
        return {"name": self.name, "unit": self.unit, "paper": self.paper,
                "ours": round(float(self.ours), 6), "tolerance": self.tolerance,
                "within_tolerance": (None if self.within_tolerance is None
                                     else bool(self.within_tolerance)),
                "basis": self.basis, "fitted_by": self.fitted_by,
                "counts_as_agreement": self.counts_as_agreement}


def _fitted(row: Row, parameter: str) -> Row:
    """``row`` marked as computed from the fitted ``parameter`` (not agreement)."""
    return replace(row, basis="fitted", fitted_by=parameter)


def _relative(name: str, unit: str, paper: float, ours: float, fraction: float) -> Row:
    return Row(name, unit, paper, ours, f"+-{fraction * 100:g} %",
               bool(abs(ours - paper) <= fraction * abs(paper)))


def _absolute(name: str, unit: str, paper: float, ours: float, band: float) -> Row:
    return Row(name, unit, paper, ours, f"+-{band:g} {unit}", bool(abs(ours - paper) <= band))


@dataclass
class Reproduction:
    """The rows and the traces the figures are drawn from."""

    rows: list[Row]
    constant: dict[str, np.ndarray]
    variable: dict[str, np.ndarray]
    gain: dict[str, np.ndarray]
    assumed_loop_delay_s: float
    analysis: dict[str, Any] = field(default_factory=dict)
    notes: dict[str, float] = field(default_factory=dict)

    def agreement(self) -> dict[str, int]:
        """How many predicted rows there are and how many are within tolerance; how many
        rows come from a fit (not counted)."""
        predicted = [row for row in self.rows if row.basis == "predicted"]
        return {"predicted_rows": len(predicted),
                "predicted_within_tolerance": sum(row.counts_as_agreement for row in predicted),
                "fitted_rows": sum(row.basis == "fitted" for row in self.rows),
                "parameters": sum(row.basis == "parameter" for row in self.rows)}

    def to_json(self) -> dict[str, Any]:
        return {"rows": [row.as_dict() for row in self.rows], "agreement": self.agreement()}


def _traces(result: Any, lane: int = 0) -> dict[str, np.ndarray]:
    data = {name: values[:, lane] for name, values in result.traces.items()}
    data["time_s"] = result.time_s
    return data


def constant_rate(model: TeleopModel, operator_spec: str, seed: int, duration_s: float
                  ) -> tuple[dict[str, np.ndarray], list[Row]]:
    """Paper 4.1: contact time, cutting force and velocity, velocity = F/B."""
    scenario = load_scenario("constant-rate")
    simulator = LockstepSimulator(model.with_gain(1.0), scenario,
                                  parse_operator_spec(operator_spec), np.array([1.0]), "clay",
                                  TRANSPARENT_SAFETY, device="cpu")
    traces = _traces(simulator.run(duration_s, 0, seed=seed, record_lanes=[0]))
    force = traces["tool_force_N"][:, 0]
    x = traces["tool_position_m"][:, 0]
    steady_x = (x > 0.04) & (x < 0.10)
    traces["cutting_force_std_N"] = np.array(np.std(force[steady_x]) if steady_x.any() else 0.0)
    traces["cutting_force_max_N"] = np.array(np.max(force[steady_x]) if steady_x.any() else 0.0)
    v = traces["tool_velocity_m_s"][:, 0]
    time = traces["time_s"]
    touching = np.flatnonzero(force > CONTACT_FORCE_N)
    contact = float(time[touching[0]]) if touching.size else float("nan")
    steady = (x > 0.04) & (x < 0.10)  # past the entry transient, before the block's end
    cutting = (x > 0.02) & (x < 0.12)
    damping = scenario.blocks[0].damping_N_s_per_m
    force_mean = float(np.mean(force[steady])) if steady.any() else float("nan")
    velocity = float(np.mean(v[cutting])) if cutting.any() else float("nan")
    velocity_steady = float(np.mean(v[steady])) if steady.any() else float("nan")
    steadiness = cutting_steadiness(time, traces["tool_force_N"], traces["tool_velocity_m_s"])
    traces["steady_window_s"] = np.array([steadiness.start_s, steadiness.end_s])
    rows = [
        _absolute("contact_time_s", "s", 0.4, contact, 0.1),
        _relative("cutting_force_N", "N", 3.6, force_mean, 0.1),
        _relative("cutting_velocity_m_s", "m/s", 0.038, velocity, 0.1),
        _relative("cutting_velocity_over_F_per_B", "1", 1.0,
                  velocity_steady / (force_mean / damping), 0.05),
        *steady_cut_rows(steadiness),
    ]
    return traces, rows


def steady_cut_rows(steadiness: Any) -> list[Row]:
    """The rows of the steady cut (the paper's Fig. 9 shows a steady 3.6 N at
    38 mm/s): over the steady part of the cut (common/records/cutting.py) the force ripple (std |ft|
    / mean) at most 10 %, no velocity reversal, mean force 3.6 +- 0.4 N, speed 34-42 mm/s."""
    ripple = steadiness.force_ripple_ratio
    reversals = steadiness.velocity_reversals
    return [
        Row("cutting_force_ripple_ratio", "1", None, ripple, "<= 0.1 (Fig. 9: steady)",
            bool(np.isfinite(ripple) and ripple <= 0.1)),
        Row("cutting_velocity_reversals", "1", 0.0, float(reversals), "none",
            steadiness.samples > 0 and reversals == 0),
        _absolute("steady_cutting_force_N", "N", 3.6, steadiness.mean_force_N, 0.4),
        _absolute("steady_cutting_speed_m_s", "m/s", 0.038, steadiness.mean_speed_m_s, 0.004),
    ]


def variable_rate(model: TeleopModel, operator_spec: str, seed: int, duration_s: float
                  ) -> tuple[dict[str, np.ndarray], list[Row]]:
    """Paper 4.2: velocity constant on each step and equal to F / p with F = 3 N."""
    scenario = load_scenario("variable-rate")
    operator = parse_operator_spec(operator_spec)
    target_N = float(operator.params.get("fx", 3.0))
    simulator = LockstepSimulator(model.with_gain(1.0), scenario, operator, np.array([1.0]),
                                  "clay", TRANSPARENT_SAFETY, device="cpu")
    traces = _traces(simulator.run(duration_s, 0, seed=seed, record_lanes=[0]))
    x = traces["tool_position_m"][:, 0]
    v = traces["tool_velocity_m_s"][:, 0]
    blocks = {block.name: block for block in scenario.blocks}
    force = traces["tool_force_N"][:, 0]
    rows, ratios = [], []
    # The operator's gains (one set for 4.1 and 4.2) were chosen among a few so that it holds
    # the force on every step, as the paper's operator did: these rows were the objective.
    fit = "lockstep.variable_rate_operator gains (chosen so the operator holds 3 N)"
    for name, damping in VARIABLE_STEPS:
        low, high = blocks[name].x_range_m
        # The cutting edge (the tool's front, radius r ahead of its centre) is on the step
        # for centres in [low - r, high - r]; the second half of that stretch is the
        # settled part the paper's staircase shows.
        radius = scenario.tool.radius_m
        middle = (low + high) / 2.0 - radius
        inside = (x > middle) & (x < high - radius)
        ours = float(np.median(v[inside])) if inside.any() else float("nan")
        held = float(np.median(force[inside])) if inside.any() else float("nan")
        rows.append(_fitted(_relative(f"variable_rate_velocity_m_s_{name}", "m/s",
                                      round(target_N / damping, 6), ours, 0.10), fit))
        ratios.append(_relative(f"variable_rate_velocity_over_F_per_B_{name}", "1", 1.0,
                                ours / (held / damping), 0.05))
    rows += ratios
    return traces, rows


def gain_experiment(model: TeleopModel, operator_spec: str, loop_delay_s: float, seed: int,
                    duration_s: float) -> tuple[dict[str, np.ndarray], list[Row]]:
    """Paper 4.3: k = 3, 13, 19 with the analysis's environment and the assumed delay."""
    scenario = load_scenario("arbitrary")
    delay_samples = int(round(loop_delay_s / model.sample_period_s))
    simulator = LockstepSimulator(model, scenario, parse_operator_spec(operator_spec),
                                  np.array(GAINS), "linear", TRANSPARENT_SAFETY)
    result = simulator.run(duration_s, delay_samples, seed=seed, record_lanes=[0, 1, 2])
    time = result.time_s
    force = np.abs(result.traces["tool_force_N"][:, :, 0])
    traces = {"time_s": time, **{f"k{int(g)}_tool_force_N": result.traces["tool_force_N"][:, i, 0]
                                 for i, g in enumerate(GAINS)}}

    def peak(lane: int, until_s: float) -> float:
        return float(np.max(force[time <= until_s, lane]))

    def first(lane: int, level_N: float) -> float:
        above = np.flatnonzero(force[:, lane] > level_N)
        return float(time[above[0]]) if above.size else float("inf")

    # The loop delay is fitted to the k = 13 trace (crossing 20 N at about 1.8 s): the k = 13
    # rows agree through the fit, not as confirmations; k = 3 and k = 19 are predictions.
    fit = "lockstep.gain_experiment_loop_delay_s (fitted to the k = 13 trace)"
    rows = [
        Row("k3_peak_force_N", "N", 6.0, peak(0, duration_s), "< 6 N (bounded)",
            peak(0, duration_s) < 6.0),
        _fitted(_relative("k13_peak_force_N", "N", 20.0, peak(1, 1.8), 0.5), fit),
        _relative("k19_peak_force_N", "N", 44.0, peak(2, 1.3), 0.5),
        _fitted(_absolute("k13_time_above_7N_s", "s", 1.5, first(1, 7.0), 0.2), fit),
        Row("k19_faster_than_k13", "1", 1.0, float(first(2, 20.0) < first(1, 20.0)),
            "k = 19 reaches 20 N first", first(2, 20.0) < first(1, 20.0)),
        Row("assumed_loop_delay_s", "s", None, delay_samples * model.sample_period_s,
            "fitted parameter (no paper number)", None, "parameter", fit),
    ]
    return traces, rows


def reproduce(config: dict[str, Any]) -> Reproduction:
    """Run the three experiments with the configuration's ``[model]`` and ``[lockstep]``."""
    model = model_from_config(config)
    section = config["lockstep"]
    seed = int(section["seed"])
    delay = float(section["gain_experiment_loop_delay_s"])
    constant, rows = constant_rate(model, section["constant_rate_operator"], seed, 3.2)
    variable, more = variable_rate(model, section["variable_rate_operator"], seed, 4.2)
    rows += more
    gain, more = gain_experiment(model, section["gain_operator"], delay, seed, 2.0)
    rows += more
    rows_by_name = {row.name: row for row in rows}
    notes = {"cutting_force_std_N": float(constant["cutting_force_std_N"]),
             "cutting_force_max_N": float(constant["cutting_force_max_N"]),
             "cutting_force_ripple_ratio": rows_by_name["cutting_force_ripple_ratio"].ours,
             "cutting_velocity_reversals": rows_by_name["cutting_velocity_reversals"].ours}
    return Reproduction(rows, constant, variable, gain, delay, gain_analysis(model, delay), notes)


def gain_analysis(model: TeleopModel, delay_s: float) -> dict[str, Any]:
    """What the analysis says about the gain experiment: the margins of k = 3, 13, 19
    (sampled), the largest k stable at the assumed delay and for every delay (sampled and
    continuous), to set against the paper's k <= 5."""
    ts = model.sample_period_s
    sampled = analyse(model, 13.0, delay_s, AnalysisSettings(sample_period_s=ts))
    continuous = analyse(model, 13.0, delay_s, AnalysisSettings())
    out: dict[str, Any] = {
        f"k{int(g)}_delay_margin_sampled_s": _finite(analytic_margin_s(model, g, ts))
        for g in GAINS}
    out.update({
        "k_max_at_assumed_delay_sampled": sampled.k_max,
        "k_max_delay_independent_sampled": sampled.k_max_delay_independent,
        "k_max_at_assumed_delay_continuous": continuous.k_max,
        "k_max_delay_independent_continuous": continuous.k_max_delay_independent,
        "paper_k_bound": 5.0,
    })
    return {key: (None if value is None else float(value)) for key, value in out.items()}


def _finite(value: float) -> float | None:
    return float(value) if np.isfinite(value) else None


def _figure(path: Path, draw: Any, xlabel: str, ylabel: str, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    draw(ax)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


FIGURES = {
    "constant_force_time.png": "4.1: cutting force against time",
    "constant_velocity_position.png": "4.1: velocity against position",
    "constant_force_position.png": "4.1: cutting force against position",
    "variable_velocity_position.png": "4.2: velocity staircase against position",
    "gain_force_time.png": "4.3: tool force for k = 3, 13, 19",
}


def write_figures(repro: Reproduction, out: Path) -> list[str]:
    """The PNG figures of the reproduction in ``out``; returns their file names."""
    c, v, g = repro.constant, repro.variable, repro.gain
    _figure(out / "constant_force_time.png",
            lambda ax: (ax.plot(c["time_s"], c["tool_force_N"][:, 0], lw=0.8),
                        ax.axhline(3.6, color="k", ls="--", lw=0.8, label="paper: 3.6 N"),
                        ax.axvline(0.4, color="r", ls=":", lw=0.8,
                                   label="paper: contact 0.4 s")),
            "time (s)", "tool force ft_x (N)", FIGURES["constant_force_time.png"])
    x = c["tool_position_m"][:, 0] * 100.0
    _figure(out / "constant_velocity_position.png",
            lambda ax: (ax.plot(x, c["tool_velocity_m_s"][:, 0], lw=0.8, label="velocity"),
                        ax.plot(x, c["tool_force_N"][:, 0] / 100.0, lw=0.8, label="F/B"),
                        ax.axhline(0.038, color="k", ls="--", lw=0.8,
                                   label="paper: 0.038 m/s"),
                        ax.set_xlim(0, 14), ax.set_ylim(-0.05, 0.15)),
            "tool position x (cm)", "m/s", FIGURES["constant_velocity_position.png"])
    _figure(out / "constant_force_position.png",
            lambda ax: (ax.plot(x, c["tool_force_N"][:, 0], lw=0.8), ax.set_xlim(0, 14)),
            "tool position x (cm)", "tool force ft_x (N)",
            FIGURES["constant_force_position.png"])
    xv = v["tool_position_m"][:, 0] * 100.0

    def staircase(ax: Any) -> None:
        ax.plot(xv, v["tool_velocity_m_s"][:, 0], lw=0.8, label="velocity")
        for index, (_, damping) in enumerate(VARIABLE_STEPS):
            low = 2.0 + 3.0 * index - 0.5
            ax.hlines(3.0 / damping, low, low + 3.0, color="k", ls="--", lw=0.8,
                      label="3 N / p" if index == 0 else None)
        ax.set_xlim(0, 18)
        ax.set_ylim(-0.1, 0.3)

    _figure(out / "variable_velocity_position.png", staircase, "tool position x (cm)",
            "velocity (m/s)", FIGURES["variable_velocity_position.png"])

    def gains(ax: Any) -> None:
        for gain in GAINS:
            ax.plot(g["time_s"], g[f"k{int(gain)}_tool_force_N"], lw=0.8, label=f"k = {gain:g}")
        ax.set_ylim(-50, 50)
        ax.axhline(6.0, color="k", ls=":", lw=0.6)

    _figure(out / "gain_force_time.png", gains, "time (s)", "tool force ft_x (N), clipped",
            FIGURES["gain_force_time.png"] + f" (loop delay {repro.assumed_loop_delay_s * 1e3:g}"
            " ms)")
    return list(FIGURES)


def report_markdown(repro: Reproduction) -> str:
    """report.md: the table, the analysis of the gain experiment, the figures."""
    lines = ["# Reproduction of Her, Hsu and Yu (2002), section 4", "",
             "Made by `haptic-sim repro` (lockstep simulator, docs/lockstep.md explains the "
             "choices and where the reproduction departs from the paper).", "",
             "A row's basis: *predicted* rows are the model's predictions and only they count "
             "as agreement; *fitted* rows are the figures a parameter was fitted to (they "
             "agree through the fit, the fitted parameter is named below the table); a "
             "*parameter* is the fitted value itself.", "",
             "| quantity | unit | paper | ours | difference | tolerance | within | basis |",
             "|---|---|---|---|---|---|---|---|"]
    for row in repro.rows:
        paper = "-" if row.paper is None else f"{row.paper:g}"
        diff = "-" if row.paper is None or not np.isfinite(row.ours) else (
            f"{row.ours - row.paper:+.4g}")
        within = ("-" if row.within_tolerance is None
                  else "yes" if row.within_tolerance else "**no**")
        lines.append(f"| {row.name} | {row.unit} | {paper} | {row.ours:.4g} | {diff} | "
                     f"{row.tolerance} | {within} | {row.basis} |")
    counts = repro.agreement()
    fits = sorted({row.fitted_by for row in repro.rows if row.fitted_by})
    lines += ["", f"Predicted rows within tolerance: {counts['predicted_within_tolerance']} of "
              f"{counts['predicted_rows']}; rows from a fit (not counted): "
              f"{counts['fitted_rows']}. Fitted: " + "; ".join(fits) + "."]
    a = repro.analysis
    delay_ms = repro.assumed_loop_delay_s * 1e3

    def ms(value: float | None) -> str:
        return "none (stable for every delay)" if value is None else f"{value * 1e3:.2f} ms"

    lines += ["", "## The gain experiment and the assumed loop delay", "",
              f"Assumed round-trip loop delay: {delay_ms:g} ms (`[lockstep] "
              "gain_experiment_loop_delay_s`). The environment is the paper's Tt of eq 33 "
              "(the linear environment), the loop its stability analysis describes.", "",
              f"- sampled delay margins: k = 3 {ms(a['k3_delay_margin_sampled_s'])}, "
              f"k = 13 {ms(a['k13_delay_margin_sampled_s'])}, "
              f"k = 19 {ms(a['k19_delay_margin_sampled_s'])};",
              f"- largest k stable at {delay_ms:g} ms: {a['k_max_at_assumed_delay_sampled']:.2f} "
              f"(sampled), {a['k_max_at_assumed_delay_continuous']:.2f} (continuous);",
              f"- largest k stable for every delay: "
              f"{a['k_max_delay_independent_sampled']:.2f} (sampled), "
              f"{a['k_max_delay_independent_continuous']:.2f} (continuous);",
              "- the paper's claim: k must not exceed 5, conservative against both bounds.", "",
              "## Where this reproduction departs from the paper", "",
              "- The gain experiment runs with the analysis's environment Tt (eq 33), not the "
              "clay: the clay, even through its contact, makes the loop unstable without "
              "delay from k = 3.2 (sampled analysis of its linearisation, B = 100 N s/m), so "
              "k = 13 and 19 would diverge at any delay (docs/lockstep.md).",
              "- The paper does not state its rig's loop delay. The assumed delay is fitted to "
              "one figure, k = 13 crossing 20 N at about 1.8 s; k = 3 and k = 19 are then "
              "predictions. k = 19 grows far faster than the paper's (44 N at 1.3 s): no single "
              "delay reproduces both traces in this model (k = 19 reaches 44 N by 1.3 s near "
              "10.5 ms, where k = 13 is stable; docs/lockstep.md has the scan).",
              f"- Constant rate: the cut is steady: over the steady part "
              f"(0.3 s after contact to 0.3 s before the contact ends) the force ripple "
              f"(std |ft| / mean) is {repro.notes['cutting_force_ripple_ratio']:.3f} with "
              f"{repro.notes['cutting_velocity_reversals']:.0f} velocity reversals; between "
              f"x = 4 and 10 cm the force's standard deviation is "
              f"{repro.notes['cutting_force_std_N']:.2f} N, its peak "
              f"{repro.notes['cutting_force_max_N']:.2f} N. The clay is rendered through a "
              "proxy with a passive spring-damper coupling (docs/clay.md); with the earlier "
              "instantaneous one-sided force B e v the same loop cut in a 9 Hz stick-slip "
              "(force 0-15 N, the tool running backwards every cycle).",
              "- Variable rate: the operator's PI gains (perception lag 70 ms, kp 0.7, ki 8 "
              "1/s, at most 6 N; the same operator as in 4.1) were chosen so that it holds "
              "3 N on every step, as the paper's operator did; the velocity rows are "
              "therefore marked fitted. The ratio v / (F / p) on each step, with the force "
              "the operator reached, is the prediction (the clay law in the loop).",
              "- The operators are scripted models (constant push, PI force regulation); their "
              "parameters are in `[lockstep]` of the configuration.", "",
              "## Figures", ""]
    for name, title in FIGURES.items():
        lines += [f"### {title}", "", f"![{title}]({name})", ""]
    return "\n".join(lines) + "\n"


def write_report(repro: Reproduction, out: Path) -> None:
    """report.md, the figures and report.json in ``out`` (created)."""
    import json

    out.mkdir(parents=True, exist_ok=True)
    write_figures(repro, out)
    (out / "report.md").write_text(report_markdown(repro))
    (out / "report.json").write_text(json.dumps({**repro.to_json(), "analysis": repro.analysis,
                                                 "notes": repro.notes}, indent=2))
