"""One work area for both sides: the handle's workspace and the tool's work area
agree, the tighter bound of each applied to both, so neither side runs on alone.

The master clamps its handle command to its workspace box (``[master.safety]
workspace_min_m``/``workspace_max_m``); the slave's work-area guard stops the tool
:data:`WORK_AREA_MARGIN_M` outside the scenario's grid. Mapped through Ah1 (``yt = Ah1 yh``)
the two boxes differ (the paper's defaults: the handle reaches +-150 mm on both axes, the
grid spans x 0..160 mm, y -20..20 mm), and where one side stopped at its bound and the other
did not, the tool ran on alone (the README session ended with the handle at 150 mm and the
tool 20 mm further) or the handle did.

:func:`shared_work_area` intersects them per axis and bound. The master clamps its command to
the ``handle`` box and the slave holds its tool inside the ``tool`` box (a wall:
``SlaveNode``'s position clamp, velocity into the wall zeroed), so at a bound both sides stop
at the same place. Both programs compute it from the same configuration at start-up and
report which side's bound applies (``limited_by``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from haptic.common.model.errors import ConfigError

#: How far the tool may leave the scenario's grid before the work-area guard stops it, m.
WORK_AREA_MARGIN_M = 0.01

HANDLE_WORKSPACE = "handle workspace"
SLAVE_WORK_AREA = "slave work area"


def slave_work_area_m(x_range_m: Sequence[float], y_range_m: Sequence[float],
                      margin_m: float = WORK_AREA_MARGIN_M) -> tuple[float, float, float, float]:
    """The tool's work area about a scenario's grid: (x_low, x_high, y_low, y_high), m."""
    return (float(x_range_m[0]) - margin_m, float(x_range_m[1]) + margin_m,
            float(y_range_m[0]) - margin_m, float(y_range_m[1]) + margin_m)


@dataclass(frozen=True)
class SharedWorkArea:
    """The box both sides hold, in each side's coordinates (m): ``handle_low_m`` and
    ``handle_high_m`` (x, y) for the master's command, ``tool_low_m`` and ``tool_high_m`` for
    the tool (``tool = Ah1 handle``); ``limited_by`` names, for x low, x high, y low and
    y high, whose bound applies (:data:`HANDLE_WORKSPACE` or :data:`SLAVE_WORK_AREA`)."""

    handle_low_m: tuple[float, float]
    handle_high_m: tuple[float, float]
    tool_low_m: tuple[float, float]
    tool_high_m: tuple[float, float]
    limited_by: tuple[str, str, str, str]

    def describe(self) -> str:
        """One line for the start-up event: the tool's box and whose bound sets each side."""
        parts = []
        for axis, index in (("x", 0), ("y", 1)):
            low, high = self.tool_low_m[index], self.tool_high_m[index]
            parts.append(f"{axis} {low * 1e3:.1f}..{high * 1e3:.1f} mm (low: "
                         f"{self.limited_by[2 * index]}, high: {self.limited_by[2 * index + 1]})")
        return "tool and handle (times Ah1) held to " + "; ".join(parts)


def shared_work_area(position_ratio: Sequence[float], handle_min_m: Sequence[float],
                     handle_max_m: Sequence[float],
                     tool_area_m: Sequence[float]) -> SharedWorkArea:
    """Intersect the handle's workspace box (``handle_min_m``, ``handle_max_m``: (x, y), m),
    mapped by Ah1 (``position_ratio``: per axis, non-zero, dimensionless), with the tool's
    work area (``tool_area_m``: x_low, x_high, y_low, y_high, m). Raises
    :class:`ConfigError` naming ``master.safety.workspace_max_m`` when they do not overlap on
    an axis (no position would be allowed on both sides)."""
    handle_low, handle_high, tool_low, tool_high = [], [], [], []
    limited_by: list[str] = []
    for index, axis in enumerate(("x", "y")):
        ratio = float(position_ratio[index])
        if not (math.isfinite(ratio) and ratio != 0.0):
            raise ConfigError("model.position_ratio_ah1", f"must be finite and non-zero on {axis}")
        mapped = sorted((ratio * float(handle_min_m[index]), ratio * float(handle_max_m[index])))
        area_low, area_high = float(tool_area_m[2 * index]), float(tool_area_m[2 * index + 1])
        low = max(mapped[0], area_low)
        high = min(mapped[1], area_high)
        if not low < high:
            raise ConfigError("master.safety.workspace_max_m", f"the handle's workspace times "
                              f"Ah1 ({mapped[0]:g}..{mapped[1]:g} m) and the slave's work area "
                              f"({area_low:g}..{area_high:g} m) do not overlap on {axis}")
        limited_by += [HANDLE_WORKSPACE if mapped[0] >= area_low else SLAVE_WORK_AREA,
                       HANDLE_WORKSPACE if mapped[1] <= area_high else SLAVE_WORK_AREA]
        tool_low.append(low)
        tool_high.append(high)
        back = sorted((low / ratio, high / ratio))  # clamped: no rounding past the workspace
        handle_low.append(max(back[0], float(handle_min_m[index])))
        handle_high.append(min(back[1], float(handle_max_m[index])))
    return SharedWorkArea((handle_low[0], handle_low[1]), (handle_high[0], handle_high[1]),
                          (tool_low[0], tool_low[1]), (tool_high[0], tool_high[1]),
                          tuple(limited_by))  # type: ignore[arg-type]


def work_area_from_config(config: dict, x_range_m: Sequence[float],
                          y_range_m: Sequence[float]) -> SharedWorkArea:
    """:func:`shared_work_area` of a validated configuration (Ah1 from ``[model]``, the
    workspace from ``[master.safety]``) and a scenario's grid ranges (m)."""
    ratio = [float(config["model"]["position_ratio_ah1"][i][i]) for i in (0, 1)]
    safety = config["master"]["safety"]
    return shared_work_area(ratio, safety["workspace_min_m"], safety["workspace_max_m"],
                            slave_work_area_m(x_range_m, y_range_m))
