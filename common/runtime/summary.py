"""The end-of-run summary of a node: one dict, printed and optionally written as JSON."""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

REQUIRED_SUMMARY_KEYS = (
    "rate_hz",
    "period_p99_error_s",
    "overruns",
    "steps",
    "link_one_way_delay_p50_s",
    "link_one_way_delay_p99_s",
    "loss_ratio",
    "max_abs_force_N",
    "watchdog_trips",
    "events",
)


#: Events kept in a summary; the rest are counted in ``events_omitted``.
MAX_SUMMARY_EVENTS = 1000


def make_summary(
    run: Mapping[str, Any],
    link: Mapping[str, Any],
    *,
    max_abs_force_N: float,
    watchdog_trips: int,
    events: Iterable[Mapping[str, Any]],
    **extra: Any,
) -> dict[str, Any]:
    """Merge the runner's (:meth:`RunStats.as_summary`) and the link's (:meth:`Link.summary`)
    keys with the node's: the largest force magnitude rendered (N), the watchdog trips and the
    events (dicts with at least ``time_s``, ``kind``, ``reason``). ``extra`` keys are added."""
    summary: dict[str, Any] = {}
    summary.update(run)
    summary.update(link)
    summary["max_abs_force_N"] = float(max_abs_force_N)
    summary["watchdog_trips"] = int(watchdog_trips)
    kept = [dict(e) for e in events]
    summary["events"] = kept[:MAX_SUMMARY_EVENTS]
    summary["events_omitted"] = max(0, len(kept) - MAX_SUMMARY_EVENTS)
    summary.update(extra)
    missing = [key for key in REQUIRED_SUMMARY_KEYS if key not in summary]
    if missing:
        raise KeyError(f"summary lacks {', '.join(missing)}")
    return summary


def json_safe(value: Any) -> Any:
    """``value`` with non-finite floats as None (JSON has no NaN or inf), recursively."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_safe(v) for v in value]
    return value


def write_json_summary(path: str | Path, summary: Mapping[str, Any]) -> None:
    """Write ``summary`` as JSON (NaN and inf become null), creating parent folders."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    target.write_text(json.dumps(json_safe(dict(summary)), indent=2, sort_keys=True) + "\n")


def finite_figure(summary: Mapping[str, Any], key: str) -> float | None:
    """``summary[key]`` when present and a finite number, else None (an older summary, a run
    of no time, NaN written as null)."""
    value = summary.get(key)
    return value if isinstance(value, int | float) and math.isfinite(value) else None


def loop_cpu_text(summary: Mapping[str, Any]) -> str | None:
    """``0.74`` of a CPU the run's process took, with ``(loop thread 330 us a tick)`` where
    known; None when the run did not report its CPU."""
    cores = finite_figure(summary, "process_cpu_cores")
    if cores is None:
        return None
    per_tick = finite_figure(summary, "loop_thread_cpu_per_step_s")
    return f"{cores:.2f}" + ("" if per_tick is None
                             else f" (loop thread {per_tick * 1e6:.0f} us a tick)")


def format_summary(summary: Mapping[str, Any]) -> str:
    """A few human-readable lines of the main figures."""

    def us(key: str) -> str:
        value = summary.get(key)
        return "n/a" if value is None or not math.isfinite(value) else f"{value * 1e6:.1f} us"

    loss = summary.get("loss_ratio")
    loss_text = "n/a" if loss is None or not math.isfinite(loss) else f"{loss * 100:.3f} %"
    stage_lines = []
    if summary.get("stages"):
        from haptic.common.runtime.stage_times import format_stages

        stage_lines.append(f"step p50 {us('step_p50_s')}  p99 {us('step_p99_s')}; stages "
                           + format_stages(summary["stages"]))
    cpu = loop_cpu_text(summary)
    if cpu is not None:
        emulator = finite_figure(summary, "rig_emulator_cpu_cores")
        stage_lines.append(f"CPU in CPUs: {cpu}" + (
            "" if emulator is None else f"; rig emulator {emulator:.2f}"))
    return "\n".join(
        [
            f"steps {summary['steps']}  rate {summary['rate_hz']:.1f} Hz  period error p99 "
            f"{us('period_p99_error_s')}  overruns {summary['overruns']}",
            f"link one-way delay p50 {us('link_one_way_delay_p50_s')}  p99 "
            f"{us('link_one_way_delay_p99_s')}  loss {loss_text}",
            f"max |force| {summary['max_abs_force_N']:.3f} N  watchdog trips "
            f"{summary['watchdog_trips']}  events {len(summary['events'])}",
            *stage_lines,
        ]
    )
