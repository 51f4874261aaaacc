"""The run summary: required keys, JSON output."""

from __future__ import annotations

import json
import math

import pytest

from haptic.common.runtime.summary import (
    REQUIRED_SUMMARY_KEYS,
    format_summary,
    make_summary,
    write_json_summary,
)

RUN = {"rate_hz": 1851.0, "period_p99_error_s": 2e-5, "overruns": 1, "steps": 18510}
LINK = {"link_one_way_delay_p50_s": 1e-4, "link_one_way_delay_p99_s": math.nan,
        "loss_ratio": 0.0}


def test_summary_has_the_required_keys_and_writes_valid_json(tmp_path):
    summary = make_summary(
        RUN, LINK, max_abs_force_N=3.5, watchdog_trips=2,
        events=[{"time_s": 1.0, "kind": "trip", "reason": "silence"}], side="master",
    )
    assert set(REQUIRED_SUMMARY_KEYS) <= set(summary)
    path = tmp_path / "out" / "summary.json"
    write_json_summary(path, summary)
    loaded = json.loads(path.read_text())
    assert loaded["link_one_way_delay_p99_s"] is None  # NaN -> null, still valid JSON
    assert loaded["watchdog_trips"] == 2 and loaded["side"] == "master"
    assert "1851.0 Hz" in format_summary(summary)
    assert "CPU " not in format_summary(summary)  # a run that did not report it


def test_the_printed_summary_says_what_cpu_the_loop_used() -> None:
    summary = make_summary({**RUN, "process_cpu_cores": 0.74, "loop_thread_cpu_per_step_s": 3.3e-4},
                           LINK, max_abs_force_N=3.5, watchdog_trips=0, events=[])
    assert "CPU in CPUs: 0.74 (loop thread 330 us a tick)" in format_summary(summary)
    summary["rig_emulator_cpu_cores"] = 0.36
    assert format_summary(summary).endswith("; rig emulator 0.36")
    summary["loop_thread_cpu_per_step_s"] = float("nan")  # a run of no tick
    assert format_summary(summary).endswith("CPU in CPUs: 0.74; rig emulator 0.36")


def test_missing_keys_are_refused():
    with pytest.raises(KeyError, match="rate_hz"):
        make_summary({}, LINK, max_abs_force_N=0.0, watchdog_trips=0, events=[])


def test_events_beyond_the_cap_are_counted_not_kept():
    from haptic.common.runtime.summary import MAX_SUMMARY_EVENTS

    events = [{"time_s": float(i), "kind": "saturate", "reason": "x"}
              for i in range(MAX_SUMMARY_EVENTS + 5)]
    summary = make_summary(RUN, LINK, max_abs_force_N=0.0, watchdog_trips=0, events=events)
    assert len(summary["events"]) == MAX_SUMMARY_EVENTS
    assert summary["events_omitted"] == 5
    assert summary["events"][-1]["time_s"] == MAX_SUMMARY_EVENTS - 1
