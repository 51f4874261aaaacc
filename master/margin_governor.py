"""The margin governor: keeps the master's Ch1 gain k inside the delay margin the analysis
gives for the round trip the link has now (docs/governor.md).

A pure block (no I/O, no clock): :meth:`MarginGovernor.update` takes the time (s) and the
echo age (s), returns the gain k to use, and appends events.

- **Round trip, measured.** Every tool message echoes the send time of the newest handle
  message the slave had used (common/wire/messages.py); ``now - echo`` of the newest tool message
  the master has is the age of the loop's information: the round trip, the slave's wait for
  its next tick and the master's poll, all on the master's clock (no clock synchronisation).
  While no new tool message comes it keeps growing, so a delay that jumps is seen during the
  silence, before the first late message. It overestimates the analysis' tau by about one
  period (the loop's own sample), which errs on the safe side.
- **tau*(k).** A table from the sampled-data analysis made at start
  (common/analysis/margin_table.py). A gain k is *usable* at round trip ``rtt`` while
  ``rtt <= safety_factor * tau*(k)``. An unusable round trip is acted on at once above
  ``urgent_factor * tau*(k)``, else once it has stayed unusable for ``confirm_s``: the band
  between is inside the margin, and a scheduling blip is not the loop's delay.
- **lower_k.** When the gain in use is not usable at the round trip now, the target becomes
  the largest table gain that is; k moves to it as a first-order lag (98 % in
  ``ramp_time_s``), so the compensators' inputs change smoothly. Both sides use the same k:
  the master sends it in every handle message and the slave scales its Ch2/Ct2 the same way
  (their designs are linear in k). With ``recover_after_s`` > 0, k goes back up one table
  step once the *peak* round trip over ``hold_s`` has allowed that step for
  ``recover_after_s``.
- **tdpa.** Instead of lowering k, request the passivity layer (an event and
  :attr:`GovernorDecision.mode_request`): the master switches its standby layer on and the
  slave follows (master/tick.py ``switch_passivity``, docs/governor.md); where the caller
  cannot switch it (``tdpa_available`` False) the governor lowers k as above and says so in
  the event.
- **Beyond every margin.** When even the lowest table gain is not stable at the round trip
  (``rtt >= tau*(k_min)``), :attr:`GovernorDecision.beyond_margin` is set: the caller puts
  the loop in its safe state unless ``--allow-unstable`` was given. The governor never picks
  a gain the table calls unstable at the measured round trip while a usable one exists.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Any

from haptic.common.analysis.margin_table import MarginTable, build_margin_table, gain_scalable
from haptic.common.config import ConfigError
from haptic.common.config.governor_schema import GOVERNOR_ACTIONS
from haptic.common.model.teleop import TeleopModel

#: Relative distance at which the lag snaps k onto its target.
_SNAP = 1e-4


@dataclass(frozen=True)
class GovernorSettings:
    """The ``[governor]`` table (times in s, ratios dimensionless)."""

    enabled: bool = False
    action: str = "lower_k"
    safety_factor: float = 0.7
    urgent_factor: float = 0.9
    confirm_s: float = 0.02
    ramp_time_s: float = 0.1
    hold_s: float = 2.0
    recover_after_s: float = 5.0
    min_gain_k: float = 1.0
    step_ratio: float = 0.8

    def __post_init__(self) -> None:
        if self.action not in GOVERNOR_ACTIONS:
            raise ValueError(f"action must be one of {', '.join(GOVERNOR_ACTIONS)}")
        if not 0.0 < self.safety_factor <= 1.0:
            raise ValueError("safety_factor must be in (0, 1]")
        if not self.safety_factor <= self.urgent_factor <= 1.0:
            raise ValueError("urgent_factor must be in [safety_factor, 1]")
        if not 0.0 <= self.confirm_s <= 1.0:
            raise ValueError("confirm_s must be in [0, 1] s")
        if not self.ramp_time_s > 0.0 or not self.hold_s > 0.0:
            raise ValueError("ramp_time_s and hold_s must be > 0")

    @classmethod
    def from_config(cls, config: dict[str, Any]) -> GovernorSettings:
        """From a validated configuration's ``[governor]`` table."""
        return cls(**config["governor"])


@dataclass(frozen=True)
class GovernorDecision:
    """One update's outcome: ``gain_k`` to use now; ``mode_request`` ("tdpa", "paper" or
    None: no change asked this update); ``beyond_margin``: no table gain is stable at the
    measured round trip."""

    gain_k: float
    mode_request: str | None = None
    beyond_margin: bool = False


@dataclass
class _Peak:
    """The maximum of a signal over a sliding window (a monotone deque: O(1) amortised)."""

    window_s: float
    samples: deque = field(default_factory=deque)

    def add(self, time_s: float, value: float) -> float:
        samples = self.samples
        while samples and samples[-1][1] <= value:
            samples.pop()
        samples.append((time_s, value))
        while samples[0][0] < time_s - self.window_s:
            samples.popleft()
        return samples[0][1]


class MarginGovernor:
    """See the module docstring. ``table``: tau*(k) (its first entry is the nominal k);
    ``tdpa_available``: whether the caller can run the passivity mode."""

    def __init__(self, settings: GovernorSettings, table: MarginTable,
                 tdpa_available: bool = False) -> None:
        self.settings = settings
        self.table = table
        self.tdpa_available = tdpa_available
        self.nominal_k = table.entries[0].k
        self.gain_k = self.nominal_k
        self.target_k = self.nominal_k
        self.rtt_s = math.nan
        """The latest round-trip estimate, s (NaN before the first echo)."""
        self.peak_rtt_s = math.nan
        self.max_rtt_s = 0.0
        self.invalid_echoes = 0
        self.last_invalid_echo: Any = None  # the message last counted there
        """Tool messages whose echoed send time is no handle message this master sent (before
        its first or after its newest): not a round trip, never used."""
        self.min_gain_used_k = self.nominal_k
        self.tdpa_requested = False
        self.beyond_margin = False
        self.events: list[dict[str, Any]] = []
        self._peak = _Peak(settings.hold_s)
        self._recover_since: float | None = None
        self._above_since: float | None = None
        self._last_time_s: float | None = None
        self._lowers_k = settings.action == "lower_k" or not tdpa_available

    # -- the table ----------------------------------------------------------------------------

    def usable(self, k: float, rtt_s: float) -> bool:
        """Whether gain ``k`` is usable at round trip ``rtt_s`` (within the safety factor)."""
        return rtt_s <= self.settings.safety_factor * self.table.margin_s(k)

    def best_gain(self, rtt_s: float) -> float | None:
        """The largest table gain usable at ``rtt_s`` (None: none is)."""
        for entry in self.table.entries:
            if self.usable(entry.k, rtt_s):
                return entry.k
        return None

    def _step_up(self, k: float) -> float | None:
        """The next table gain above ``k`` (None at the top)."""
        above = [e.k for e in self.table.entries if e.k > k * (1.0 + _SNAP)]
        return min(above) if above else None

    # -- the block ----------------------------------------------------------------------------

    def update(self, time_s: float, echo_age_s: float | None) -> GovernorDecision:
        """One tick at ``time_s`` (s): ``echo_age_s`` is now minus the echoed send time of the
        newest tool message (s; None: no echo yet). Returns the gain to use now."""
        dt = 0.0 if self._last_time_s is None else max(0.0, time_s - self._last_time_s)
        self._last_time_s = time_s
        if echo_age_s is None or not math.isfinite(echo_age_s):
            return GovernorDecision(self._ramp(dt))
        rtt = max(0.0, echo_age_s)
        self.rtt_s = rtt
        self.peak_rtt_s = peak = self._peak.add(time_s, rtt)
        if rtt > self.max_rtt_s:
            self.max_rtt_s = rtt
        mode_request = None
        settings = self.settings
        # 1. the gain in use (or the one being approached) must be usable at the round trip now:
        # acted on at once above urgent_factor tau*, else once it has stayed unusable for
        # confirm_s (a scheduling blip of a few ms is not the loop's delay)
        current = max(self.gain_k, self.target_k)
        usable = self.usable(current, rtt)
        if usable:
            self._above_since = None
        elif self._above_since is None:
            self._above_since = time_s
        if not usable:
            self._recover_since = None
            if self._confirmed(time_s, current, rtt):
                best = self.best_gain(rtt)
                if self._lowers_k:
                    target = best if best is not None else self.table.entries[-1].k
                    if target < self.target_k:
                        self._event(time_s, "governor_lower_k",
                                    f"{self._cause(time_s, current, rtt)}: "
                                    f"k {self.target_k:.3g} -> {target:.3g}"
                                    + ("" if settings.action == "lower_k" else
                                       " (tdpa requested, but this build has no tdpa mode)"))
                        self.target_k = target
                elif not self.tdpa_requested:
                    self.tdpa_requested = True
                    mode_request = "tdpa"
                    self._event(time_s, "governor_tdpa_request",
                                self._cause(time_s, current, rtt))
        # 2. back up (one step, or out of tdpa) once the peak allowed it long enough
        elif settings.recover_after_s > 0.0:
            if self._lowers_k:
                up = self._step_up(self.target_k)
                allowed = up is not None and self.usable(up, peak)
            else:
                up = None
                allowed = self.tdpa_requested and self.usable(self.nominal_k, peak)
            if not allowed:
                self._recover_since = None
            elif self._recover_since is None:
                self._recover_since = time_s
            elif time_s - self._recover_since >= settings.recover_after_s:
                self._recover_since = None
                if up is not None:
                    self._event(time_s, "governor_raise_k",
                                f"peak round trip {peak * 1e3:.1f} ms over {settings.hold_s:g} s"
                                f" allows k {up:.3g} (tau* {self.table.margin_s(up) * 1e3:.1f} "
                                f"ms): k {self.target_k:.3g} -> {up:.3g}")
                    self.target_k = up
                else:
                    self.tdpa_requested = False
                    mode_request = "paper"
                    self._event(time_s, "governor_paper_request",
                                f"peak round trip {peak * 1e3:.1f} ms allows k "
                                f"{self.nominal_k:.3g} again")
        # 3. beyond every margin: no table gain is stable at this round trip
        beyond = rtt >= self.table.margin_s(self.table.entries[-1].k) and not (
            self.tdpa_requested)
        if beyond and not self.beyond_margin:
            self._event(time_s, "governor_beyond_margin",
                        f"round trip {rtt * 1e3:.1f} ms beyond tau* of every k down to "
                        f"{self.table.entries[-1].k:.3g} "
                        f"({self.table.margin_s(self.table.entries[-1].k) * 1e3:.1f} ms)")
        self.beyond_margin = beyond
        return GovernorDecision(self._ramp(dt), mode_request, beyond)

    def _confirmed(self, time_s: float, k: float, rtt_s: float) -> bool:
        """Whether an unusable round trip for gain ``k`` is acted on now: above
        ``urgent_factor`` tau*(k), or unusable for ``confirm_s`` since ``_above_since``."""
        if rtt_s > self.settings.urgent_factor * self.table.margin_s(k):
            return True
        return time_s - self._above_since >= self.settings.confirm_s - 1e-12

    def _cause(self, time_s: float, k: float, rtt_s: float) -> str:
        """Why an event fired: the round trip against the factor of tau*(k) it passed (and
        for how long, below ``urgent_factor``)."""
        settings, margin = self.settings, self.table.margin_s(k)
        if rtt_s > settings.urgent_factor * margin:
            factor, held = settings.urgent_factor, ""
        else:
            factor = settings.safety_factor
            held = f" for {(time_s - self._above_since) * 1e3:.0f} ms"
        return (f"round trip {rtt_s * 1e3:.1f} ms > {factor:g} x tau*({k:.3g}) = "
                f"{margin * 1e3:.1f} ms{held}")

    def _ramp(self, dt: float) -> float:
        """Move k towards the target: a first-order lag, 98 % in ``ramp_time_s``."""
        k, target = self.gain_k, self.target_k
        if k != target:
            alpha = 1.0 - math.exp(-4.0 * dt / self.settings.ramp_time_s)
            k += (target - k) * alpha
            if abs(k - target) <= _SNAP * target:
                k = target
            self.gain_k = k
            if k < self.min_gain_used_k:
                self.min_gain_used_k = k
        return k

    def _event(self, time_s: float, kind: str, reason: str) -> None:
        self.events.append({"time_s": time_s, "kind": kind, "reason": reason})

    # -- reporting ----------------------------------------------------------------------------

    def status(self) -> str:
        """A few words for the status line: k (and its target) and the round trip."""
        rtt = "-" if math.isnan(self.rtt_s) else f"{self.rtt_s * 1e3:.1f} ms"
        k = f"k {self.gain_k:.3g}"
        if abs(self.gain_k - self.target_k) > _SNAP * self.target_k:
            k += f"->{self.target_k:.3g}"
        extra = (" TDPA" if self.tdpa_available else " TDPA?") if self.tdpa_requested else ""
        extra += " BEYOND MARGIN" if self.beyond_margin else ""
        return f"  gov {k} rtt {rtt}{extra}"

    def summary(self) -> dict[str, Any]:
        """The run summary's ``governor_*`` keys."""
        return {
            "governor_action": self.settings.action,
            "governor_nominal_k": self.nominal_k,
            "governor_final_k": self.gain_k,
            "governor_min_k": self.min_gain_used_k,
            "governor_max_round_trip_s": self.max_rtt_s,
            "governor_invalid_echoes": self.invalid_echoes,
            "governor_tdpa_requested": self.tdpa_requested,
            "governor_beyond_margin": self.beyond_margin,
            "governor_table": self.table.as_dict(),
        }


def governor_for(model: TeleopModel, config: dict[str, Any],
                 tdpa_available: bool = False) -> MarginGovernor:
    """The governor of a validated configuration for ``model`` (its k is the nominal one):
    builds the tau*(k) table from the sampled analysis (a second or two). Raises
    :class:`ConfigError` naming ``governor.action`` when k cannot be lowered on this model
    (a compliance Sh or St makes the design non-linear in k)."""
    settings = GovernorSettings.from_config(config)
    if (settings.action == "lower_k" or not tdpa_available) and not gain_scalable(model):
        raise ConfigError("governor.action", "lower_k needs compensators linear in k "
                          "(Sh = St = 0 on both axes); this model has a compliance")
    table = build_margin_table(model, config["analysis"], settings.min_gain_k,
                               settings.step_ratio)
    return MarginGovernor(settings, table, tdpa_available)
