"""What ``haptic-session`` says around its figures (common/launch/guidance.py): the wall time to
expect before it starts, and, under a missed real-time verdict, what it means, what still holds
(each claim checked against its figure) and what to try."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from haptic.common.launch.guidance import (
    expected_duration_line,
    kernels_cached,
    missed_guidance_lines,
    warp_kernel_cache_dir,
    what_still_holds,
)

GOOD_CUT = {"cut_mean_force_N": 3.55, "cut_mean_speed_m_s": 0.0382,
            "final_position_gap_m": [0.0002, -0.0001]}


def test_the_cache_folder_is_the_one_warp_itself_uses(tmp_path, monkeypatch) -> None:
    """Found without importing Warp, and the same folder Warp's own init picks."""
    monkeypatch.setenv("WARP_CACHE_PATH", str(tmp_path / "kernels"))
    assert warp_kernel_cache_dir() == tmp_path / "kernels"
    monkeypatch.delenv("WARP_CACHE_PATH")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    ours = warp_kernel_cache_dir()
    theirs = subprocess.run(
        [sys.executable, "-c", "import warp as wp; wp.config.quiet = True; wp.init(); "
         "print(wp.config.kernel_cache_dir)"],
        capture_output=True, text=True, check=True,
        env={"XDG_CACHE_HOME": str(tmp_path / "xdg"), "HOME": str(Path.home()),
             "PATH": "/usr/bin:/bin"}).stdout.strip().splitlines()[-1]
    assert Path(theirs) == ours


def test_a_cache_counts_as_warm_only_with_this_projects_kernels(tmp_path) -> None:
    assert not kernels_cached(None)
    assert not kernels_cached(tmp_path / "missing")
    (tmp_path / "wp_other.module_123").mkdir()
    assert not kernels_cached(tmp_path)
    (tmp_path / "wp_haptic.slave_sim.clay.kernels_abc").mkdir()
    assert kernels_cached(tmp_path)


def test_the_start_line_says_how_long_and_why_a_first_run_is_longer() -> None:
    warm = expected_duration_line(4.0, cached=True)
    cold = expected_duration_line(4.0, cached=False)
    assert "expect about 18 s of wall time: 4 s of the rig's time" in warm
    assert "compiles Warp's kernels" not in warm
    assert "this first run on the machine also compiles Warp's kernels" in cold


def test_what_still_holds_is_claimed_only_where_the_figures_show_it() -> None:
    assert what_still_holds(GOOD_CUT, 0.001, trips_during_run=0) == [
        "the cut matches the paper (3.6 N at 38 mm/s, within 15 %)",
        "the tool ends aligned with the handle (<= 1 mm)",
        "no watchdog tripped"]
    slow_cut = {**GOOD_CUT, "cut_mean_speed_m_s": 0.0182}
    apart = {**GOOD_CUT, "final_position_gap_m": [0.004, 0.0]}
    assert not any("cut" in text for text in what_still_holds(slow_cut, 0.001, 0))
    assert not any("aligned" in text for text in what_still_holds(apart, 0.001, 0))
    assert what_still_holds({"cut_mean_force_N": float("nan")}, 0.001, 2) == []


def test_a_missed_verdict_says_what_it_means_and_what_to_try() -> None:
    lines = "\n".join(missed_guidance_lines(GOOD_CUT, 0.001, trips_during_run=0))
    assert "what this means: some ticks ran late" in lines
    assert "still holds: the cut matches the paper" in lines
    assert "--rig model" in lines and "quieter host" in lines


def test_the_session_summary_explains_a_miss_and_is_silent_when_met() -> None:
    from haptic.common.launch.cli import combined_summary

    def side(**changes) -> dict:
        base = {"period_s": 0.00054, "rate_hz": 1851.0, "overrun_ratio": 0.0, "steps": 7407,
                "period_p99_error_s": 20e-6, "duration_s": 4.0, "events": [],
                "link_one_way_delay_p50_s": 3e-5, "link_one_way_delay_p99_s": 1e-4,
                "loss_ratio": 0.0, "max_abs_force_N": 4.0, "overruns": 0}
        return {**base, **changes}

    cut = {**GOOD_CUT, "cutting_time_s": 2.4, "cut_mean_handle_force_N": 3.6,
           "cutting_mean_force_N": 3.6, "cutting_mean_speed_m_s": 0.038}
    met = combined_summary(side(), side(**cut), cpus=2)
    assert "real time: met" in met and "what this means" not in met
    missed = combined_summary(side(overrun_ratio=0.02), side(**cut), cpus=2)
    assert "real time: MISSED: master overruns 2.00 %" in missed
    assert "what this means" in missed and "to try:" in missed
