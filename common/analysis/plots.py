"""PNG plots of the analysis: Nyquist, compensator Bode plots and the stability map."""

from __future__ import annotations

from pathlib import Path

import control
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from haptic.common.analysis.report import Analysis, AnalysisSettings, axis_loop  # noqa: E402
from haptic.common.analysis.stability_map import StabilityMap  # noqa: E402
from haptic.common.model.synthesis import synthesize  # noqa: E402
from haptic.common.model.teleop import TeleopModel, evaluate_tf  # noqa: E402


def plot_nyquist(model: TeleopModel, analysis: Analysis, settings: AnalysisSettings,
                 path: Path) -> Path:
    """Nyquist plot of L = Delta - 1 per axis at the analysed delay; -1 is the critical
    point (encirclements of -1 by L are encirclements of 0 by Delta)."""
    fig, axes = plt.subplots(1, len(model.axes), figsize=(6 * len(model.axes), 5.5))
    upper = settings.max_frequency_rad_s
    if settings.sample_period_s is not None:
        upper = min(upper, np.pi / settings.sample_period_s)
    omega = np.geomspace(1e-2, upper, 20000)
    for plot, axis, verdict in zip(np.atleast_1d(axes), model.axes, analysis.axes, strict=True):
        loop = axis_loop(model, axis, analysis.k, settings)
        value = loop.terms(omega).characteristic(analysis.delay_s) - 1.0
        plot.plot(value.real, value.imag, color="C0", lw=1.0, label="w > 0")
        plot.plot(value.real, -value.imag, color="C0", lw=0.8, ls="--", label="w < 0")
        plot.plot([-1.0], [0.0], "rx", ms=10, mew=2, label="-1")
        plot.set_xlim(-4.0, 2.0)
        plot.set_ylim(-3.0, 3.0)
        plot.set_aspect("equal")
        plot.grid(True, alpha=0.3)
        state = "stable" if verdict.stable else "UNSTABLE"
        plot.set_title(f"axis {axis.name}: k = {analysis.k:g}, tau = "
                       f"{analysis.delay_s * 1e3:.2f} ms, {state}")
        plot.set_xlabel("Re L(jw)")
        plot.set_ylabel("Im L(jw)")
        plot.legend(loc="lower right", fontsize=8)
    fig.suptitle("Nyquist plot of L = Delta(jw, tau) - 1 (window around -1; L -> inf at w -> 0)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_compensator_bode(model: TeleopModel, k: float, path: Path) -> Path:
    """Bode plots of Ch1, Ct1, Ch2, Ct2 per axis, continuous and Tustin at Ts."""
    omega = np.geomspace(1e-1, 0.99 * np.pi / model.sample_period_s, 800)
    fig, (mag, phase) = plt.subplots(2, 1, figsize=(9, 7), sharex=True)
    for style, compensators in zip(("-", ":"), synthesize(model.with_gain(k)), strict=False):
        for color, (name, system) in zip(("C0", "C1", "C2", "C3"),
                                         compensators.as_dict().items(), strict=True):
            response = evaluate_tf(system, 1j * omega)
            discrete = control.sample_system(system, model.sample_period_s, method="tustin")
            response_d = evaluate_tf(discrete, np.exp(1j * omega * model.sample_period_s))
            label = f"{name} ({compensators.axis})"
            mag.semilogx(omega, 20 * np.log10(np.abs(response)), style, color=color, label=label)
            mag.semilogx(omega, 20 * np.log10(np.abs(response_d)), style, color=color, alpha=0.35)
            phase.semilogx(omega, np.degrees(np.unwrap(np.angle(response))), style, color=color)
            phase.semilogx(omega, np.degrees(np.unwrap(np.angle(response_d))), style,
                           color=color, alpha=0.35)
    mag.set_ylabel("magnitude, dB (m/N for Ch1, Ct1; N/N for Ch2, Ct2)")
    phase.set_ylabel("phase, deg")
    phase.set_xlabel("frequency, rad/s")
    mag.set_title(f"Compensators at k = {k:g} (solid x, dotted y; faint: Tustin at Ts)")
    mag.legend(ncol=2, fontsize=8)
    for plot in (mag, phase):
        plot.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_stability_map(result: StabilityMap, analysis: Analysis, path: Path,
                       title: str = "Stability over gain and round-trip delay") -> Path:
    """Cells evaluated one by one (green stable, red unstable), the analytic delay-margin
    boundary over them, and the analysed point."""
    fig, plot = plt.subplots(figsize=(8, 5.5))
    gains, delays = result.gains_k, result.delays_s * 1e3
    plot.pcolormesh(gains, delays, result.stable.T.astype(float), cmap="RdYlGn", vmin=-0.3,
                    vmax=1.3, shading="nearest", alpha=0.6)
    finite = np.isfinite(result.delay_margin_s)
    plot.plot(gains[finite], result.delay_margin_s[finite] * 1e3, "k-", lw=2,
              label="analytic delay margin tau*(k)")
    if analysis.k_max_delay_independent is not None:
        plot.axvline(analysis.k_max_delay_independent, color="k", ls="--", lw=1,
                     label=f"delay-independent bound k = {analysis.k_max_delay_independent:.3g}")
    plot.plot([analysis.k], [analysis.delay_s * 1e3], "b*", ms=14, label="analysed point")
    plot.set_xscale("log")
    plot.set_ylim(delays[0], delays[-1])
    plot.set_xlabel("Ch1 gain k")
    plot.set_ylabel("round-trip delay, ms")
    plot.set_title(title)
    plot.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
