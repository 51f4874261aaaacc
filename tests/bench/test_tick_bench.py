"""The tick benchmark, briefly: it drives the programs' ticks as they run (the slave's
pacing takes 0 to 3 node steps a tick from the scripted deliveries) and its figures add up.
No time is asserted (timing is the benchmark's output, not a test)."""

from __future__ import annotations

import json


def test_deliveries_average_one_sample_a_tick(load_bench) -> None:
    bench = load_bench("tick_bench")
    groups = bench.delivery_groups(5000, 0.05, 0.02, seed=1)
    assert len(groups) == 5000
    assert set(groups) == {0, 1, 2, 3}
    assert abs(sum(groups) - len(groups)) <= 3  # a gap's samples come with the next tick


def test_json_figures_add_up(load_bench, capsys) -> None:
    bench = load_bench("tick_bench")
    assert bench.main(["--ticks", "600", "--warmup", "300", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    slave, master = result["slave"], result["master"]
    # the tool runs and the handle's forces are on through the measured ticks
    assert slave["running_fraction"] == 1.0 and master["enabled_fraction"] == 1.0
    counts = {int(k): v for k, v in slave["steps_per_tick"].items()}
    assert sum(counts.values()) == 600
    assert {0, 1, 2} <= set(counts) and max(counts) <= 4  # gaps and their catch-up ticks
    by_steps = slave["node_by_steps"]
    assert {int(k): v["count"] for k, v in by_steps.items()} == counts
    assert slave["node_per_step"]["count"] == 600 - counts[0]
    for side in (slave, master):
        for figures in side["stages"].values():
            assert figures["count"] == 600
            assert 0 < figures["p50_us"] <= figures["p99_us"] <= figures["max_us"]
    bench.print_table(result)
    assert "slave  node per step" in capsys.readouterr().out
