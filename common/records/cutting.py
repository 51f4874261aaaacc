"""Figures of a cut from a trace: how long the tool was in the clay, the mean force and
speed there (:func:`cutting_figures`), and how steady the cut was (:func:`cutting_steadiness`,
:func:`steady_cut_fields`). Pure numpy on the trace's named columns, so the slave, the
session, the replay and the lockstep reproduction share them.

How steady a cut is (the figures of a constant-rate cut):

Over the steady part of a cut, from ``settle_s`` (0.3 s) after first contact to ``settle_s``
before the contact ends (the tool leaving the block, or the end of the record while still
cutting), :func:`cutting_steadiness` gives

- ``force_ripple_ratio``: the standard deviation of |ft| over its mean (the vibration an
  operator feels in the hand; a stick-slip cycle gives about 1, a steady cut a few %);
- ``velocity_reversals``: how many times the tool's velocity along the cut (the direction of
  its mean velocity over the window) turns from forward to backward;
- the mean |ft| (N) and the mean speed along the cut (m/s).

Contact is |ft| above ``contact_force_N``. The lockstep reproduction (``haptic-sim repro``)
and a session's summary call the same function, so the two report the same figures.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

#: |ft| above this counts as contact, N.
CONTACT_FORCE_N = 0.05
#: The steady part starts this long after first contact and ends this long before the
#: contact ends, s.
SETTLE_S = 0.3


@dataclass(frozen=True)
class CuttingSteadiness:
    """The steadiness figures of one cut (see the module docstring); ``samples`` is the
    number of samples in the steady window (0: no steady part, the figures are NaN)."""

    contact_s: float
    leave_s: float
    start_s: float
    end_s: float
    samples: int
    mean_force_N: float
    mean_speed_m_s: float
    force_ripple_ratio: float
    velocity_reversals: int

    def as_dict(self) -> dict[str, Any]:
        """Plain floats and ints (NaN as None), for JSON."""
        return {key: (None if isinstance(value, float) and not np.isfinite(value) else value)
                for key, value in asdict(self).items()}


def _magnitude(values: np.ndarray) -> np.ndarray:
    values = np.asarray(values, float)
    return np.abs(values) if values.ndim == 1 else np.sqrt((values * values).sum(axis=1))


def cutting_steadiness(time_s: np.ndarray, tool_force_N: np.ndarray,
                       tool_velocity_m_s: np.ndarray, *,
                       contact_force_N: float = CONTACT_FORCE_N,
                       settle_s: float = SETTLE_S) -> CuttingSteadiness:
    """The steadiness of the cut in a trace: ``time_s`` (n,), ``tool_force_N`` and
    ``tool_velocity_m_s`` (n,) along one axis or (n, 2)."""
    time = np.asarray(time_s, float)
    force = _magnitude(tool_force_N)
    velocity = np.asarray(tool_velocity_m_s, float)
    if velocity.ndim == 1:
        velocity = velocity[:, None]
    nan = float("nan")
    touching = np.flatnonzero(force > contact_force_N)
    if touching.size == 0:
        return CuttingSteadiness(nan, nan, nan, nan, 0, nan, nan, nan, 0)
    contact, leave = float(time[touching[0]]), float(time[touching[-1]])
    start, end = contact + settle_s, leave - settle_s
    window = (time >= start) & (time <= end)
    samples = int(window.sum())
    if samples < 2:
        return CuttingSteadiness(contact, leave, start, end, samples, nan, nan, nan, 0)
    mean_velocity = velocity[window].mean(axis=0)
    norm = float(np.linalg.norm(mean_velocity))
    direction = mean_velocity / norm if norm > 0.0 else np.eye(velocity.shape[1])[0]
    along = velocity[window] @ direction
    # a reversal: each run of samples moving backward (< 0) along the cut
    backward = along < 0.0
    reversals = int(np.count_nonzero(backward[1:] & ~backward[:-1])) + int(backward[0])
    mean_force = float(force[window].mean())
    ripple = float(force[window].std() / mean_force) if mean_force > 0.0 else float("inf")
    return CuttingSteadiness(contact, leave, start, end, samples, mean_force,
                             float(along.mean()), ripple, reversals)


def steady_cut_fields(trace: dict[str, np.ndarray]) -> dict[str, Any]:
    """The steadiness of a slave trace (``time_s``, ``tool_force_x_N``, ``tool_force_y_N``,
    ``tool_velocity_x_m_s``, ``tool_velocity_y_m_s``) as summary fields:
    ``cutting_force_ripple_ratio``, ``cutting_velocity_reversals``, ``steady_cut_force_N``,
    ``steady_cut_speed_m_s``, ``steady_cut_start_s``, ``steady_cut_end_s`` (None when the trace
    has no steady part). For a session's summary and report."""
    names = ("time_s", "tool_force_x_N", "tool_force_y_N", "tool_velocity_x_m_s",
             "tool_velocity_y_m_s")
    empty = {"cutting_force_ripple_ratio": None, "cutting_velocity_reversals": None,
             "steady_cut_force_N": None, "steady_cut_speed_m_s": None,
             "steady_cut_start_s": None, "steady_cut_end_s": None}
    if not trace or any(name not in trace for name in names) or trace["time_s"].size < 2:
        return empty
    steady = cutting_steadiness(
        trace["time_s"], np.column_stack([trace["tool_force_x_N"], trace["tool_force_y_N"]]),
        np.column_stack([trace["tool_velocity_x_m_s"], trace["tool_velocity_y_m_s"]]))
    if steady.samples < 2:
        return empty
    return {"cutting_force_ripple_ratio": steady.force_ripple_ratio,
            "cutting_velocity_reversals": steady.velocity_reversals,
            "steady_cut_force_N": steady.mean_force_N,
            "steady_cut_speed_m_s": steady.mean_speed_m_s,
            "steady_cut_start_s": steady.start_s, "steady_cut_end_s": steady.end_s}


def cutting_figures(trace: dict[str, np.ndarray]) -> dict[str, Any]:
    """Figures of the cut from the trace, over the span from the first to the last traced
    sample that removed clay with forces enabled: its duration (s), the time-averaged tool
    force magnitude (N) and received handle force x (N), and the mean speed (distance over
    time, m/s); plus the mean force magnitude (N) and speed (m/s) over the removing samples
    alone. ``None`` figures when the tool never cut."""
    none = {"cutting_time_s": 0.0, "cut_mean_force_N": None, "cut_mean_speed_m_s": None,
            "cut_mean_handle_force_N": None, "cutting_mean_force_N": None,
            "cutting_mean_speed_m_s": None}
    if not trace or trace["time_s"].size < 2:
        return none
    cutting = (trace["cutting"] > 0.5) & (trace["forces_enabled"] > 0.5)
    if cutting.sum() < 2:
        return none
    indices = np.flatnonzero(cutting)
    span = slice(indices[0], indices[-1] + 1)
    times = trace["time_s"]
    duration = float(times[indices[-1]] - times[indices[0]])
    if duration <= 0.0:
        return none
    force = np.hypot(trace["tool_force_x_N"], trace["tool_force_y_N"])
    speed = np.hypot(trace["tool_velocity_x_m_s"], trace["tool_velocity_y_m_s"])
    distance = float(np.hypot(trace["tool_position_x_m"][indices[-1]]
                              - trace["tool_position_x_m"][indices[0]],
                              trace["tool_position_y_m"][indices[-1]]
                              - trace["tool_position_y_m"][indices[0]]))
    return {"cutting_time_s": duration,
            "cut_mean_force_N": float(force[span].mean()),
            "cut_mean_speed_m_s": distance / duration,
            "cut_mean_handle_force_N": float(trace["handle_force_x_N"][span].mean()),
            "cutting_mean_force_N": float(force[cutting].mean()),
            "cutting_mean_speed_m_s": float(speed[cutting].mean())}
