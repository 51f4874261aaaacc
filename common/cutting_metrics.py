"""Figures of a cut from a slave trace (haptic-slave's ``--out``, a recording's
``/slave/state``): how long the tool was in the clay, the mean force and speed there.
Pure numpy on the trace's named columns, so the slave, the session and the replay share it.
"""

from __future__ import annotations

from typing import Any

import numpy as np


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
