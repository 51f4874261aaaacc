"""The sweep's default grids live in one place (lockstep/sweep.py): ``haptic-sim sweep`` and
bench/latency_sweep.py run the same cells, and the clay mode runs the clay grid, not the
linear loop's gains (k up to 30, far past every clay margin)."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path
from typing import Any

import pytest

import haptic.lockstep.sweep as sweep
from haptic.lockstep.cli import main

BENCH = Path(__file__).resolve().parents[2] / "bench" / "latency_sweep.py"


def _bench_settings(quick: bool, mode: str) -> Any:
    """bench/latency_sweep.py's grid (the script loaded as a module)."""
    spec = importlib.util.spec_from_file_location("latency_sweep", BENCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.settings_for(quick, mode)


def _settings_run_by(monkeypatch: pytest.MonkeyPatch, argv: list[str]) -> Any:
    """The SweepSettings ``haptic-sim`` hands to the sweep (nothing is simulated)."""
    seen: dict[str, Any] = {}

    def fake_grid(model: Any, settings: Any, *_: Any) -> tuple[dict, list]:
        seen["settings"] = settings
        raise SystemExit(0)

    monkeypatch.setattr(sweep, "run_sweep_grid", fake_grid)
    with pytest.raises(SystemExit):
        main(argv)
    return seen["settings"]


@pytest.mark.parametrize("quick", [False, True])
@pytest.mark.parametrize("mode", ["linear", "clay"])
def test_the_command_and_the_benchmark_run_the_same_grid(monkeypatch, mode: str,
                                                         quick: bool) -> None:
    shared = sweep.default_settings(mode, quick)
    argv = ["sweep", "--mode", mode] + (["--quick"] if quick else [])
    settings = _settings_run_by(monkeypatch, argv)
    assert settings.gains_k == shared.gains_k
    assert settings.delays_s == shared.delays_s
    assert settings.duration_s == shared.duration_s
    assert settings.reference_start_s == shared.reference_start_s
    assert _bench_settings(quick, mode) == shared


def test_the_clay_grid_stays_where_the_clay_margins_are() -> None:
    clay = sweep.default_settings("clay")
    assert clay.gains_k == sweep.CLAY_GAINS and max(clay.gains_k) <= 1.5
    assert len(clay.delays_s) == 21 and clay.delays_s[-1] == pytest.approx(0.020)
    assert clay.duration_s == sweep.CLAY_DURATION_S


@pytest.mark.slow
def test_the_quick_clay_sweep_passes_its_own_check(capsys) -> None:
    """55 cells of Warp clay on the CPU (about 13 s on a 2-core VM)."""
    assert main(["sweep", "--mode", "clay", "--quick", "--json", "--check"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["cells"] == 55 and summary["disagree_outside_band"] == 0
