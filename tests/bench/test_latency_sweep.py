"""The latency-sweep benchmark end to end on a tiny grid: its JSON has the fields the issue
asks for and --check passes when every cell agrees. No figure is asserted."""

from __future__ import annotations

import json

from haptic.lockstep.sweep import SweepSettings


def test_json_shape_and_check(load_bench, capsys, monkeypatch) -> None:
    bench = load_bench("latency_sweep")
    monkeypatch.setattr(bench, "settings_for", lambda quick, mode: SweepSettings(
        (3.0, 19.0), (0.0, 0.012), "linear", 1.5))
    assert bench.main(["--quick", "--json", "--check"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert {"cells", "agree", "disagree", "disagree_outside_band", "simulated_seconds",
            "wall_seconds", "sim_per_wall"} <= set(result)
    assert result["cells"] == 4 and result["disagree_outside_band"] == 0


def test_a_device_it_cannot_use_is_refused(load_bench, capsys) -> None:
    """--device: one config-error line and exit status 2 before anything runs."""
    bench = load_bench("latency_sweep")
    assert bench.main(["--mode", "clay", "--device", "cuda:01"]) == 2
    assert capsys.readouterr().err.strip().endswith(
        "config error: --device: must be auto, cpu, cuda or cuda:N (got 'cuda:01')")
