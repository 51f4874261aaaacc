"""The loop benchmark end to end, briefly: its JSON has the shape issue 5 asks for. No figure
is asserted (timing is the benchmark's output, not a test)."""

from __future__ import annotations

import json

import pytest


def test_json_shape(load_bench, capsys, monkeypatch):
    bench = load_bench("loop_bench")
    real = bench.raw_ping_pong
    monkeypatch.setattr(bench, "raw_ping_pong",
                        lambda *_args, period_s=0.0: real(300, 20, period_s=period_s))
    assert bench.main(["--duration", "1.0", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    for side in ("master", "slave"):
        assert {"rate_hz", "period_p99_error_s", "overrun_ratio"} <= set(result[side])
        assert result[side]["steps"] > 0
    assert {"one_way_p50_s", "one_way_p99_s", "loss_ratio"} <= set(result["link"])
    assert {"one_way_p50_s", "one_way_p99_s"} <= set(result["raw_zenoh"])
    assert result["raw_zenoh"]["round_trips"] == 600
    assert result["raw_zenoh_paced"]["round_trips"] == 600
    assert result["raw_zenoh_paced"]["period_s"] == 0.00054
    assert result["link_to_raw_p50_ratio"] > 0
    assert result["cpu_layout"] == "partitioned"
    # the slave program got the layout's phase margin (its summary says the lag it ran)
    assert result["slave_run_options"] == bench.slave_layout_args("partitioned")
    if result["slave_run_options"]:  # two CPUs or more: the 20 us spin plus the margin
        assert result["phase_lock"]["lag_s"] == pytest.approx(
            2e-5 + bench.PARTITIONED_SLAVE_MARGIN_S)
    # the programs' default request, held by the bench too (or refused, and said why)
    assert (result["cpu_latency_limit_us"] == 0) != bool(result["cpu_latency_warning"])
    assert result["slave"]["step_p50_s"] > 0
    # the slave's node steps per tick (slave_sim/pacing.py); the master has no pacing
    pacing = result["slave"]["pacing"]
    assert pacing["follow_master_samples"] is True
    assert {"waited_ticks", "caught_up_steps", "max_tick_steps", "max_backlog_samples"} <= set(
        pacing)
    assert pacing["max_tick_steps"] >= 1
    assert result["master"]["pacing"] is None
    # what the node stage's p99 holds: its time per node step and the ticks by node steps
    by_steps = result["slave"]["node_steps_per_tick"]
    assert sum(entry["ticks"] for entry in by_steps.values()) > 0
    assert max(int(steps) for steps in by_steps) == pacing["max_tick_steps"]
    per_step = result["slave"]["node_per_step"]
    assert per_step["ticks"] == sum(entry["ticks"] for steps, entry in by_steps.items()
                                    if steps != "0")
    assert 0 < per_step["p50_s"] <= per_step["max_s"]
    assert "node_per_step" not in result["master"]
    bench.print_table(result)
    table = capsys.readouterr().out
    assert f"node steps: {pacing['waited_ticks']} ticks waited, {pacing['caught_up_steps']} " \
        "caught up" in table
    assert table.count("node steps:") == 1
    assert table.count("node part per node step") == 1


def test_cpu_layouts(load_bench):
    bench = load_bench("loop_bench")
    two = bench.cpu_layout_args("partitioned", [0, 1])
    assert two == ["--rt-priority", "40", "--loop-cpus", "1", "--other-cpus", "0",
                   "--spin-s", "0.00002"]
    allowed = bench.cpu_layout_args("partitioned", [2, 3, 5])  # e.g. under taskset
    assert allowed[allowed.index("--loop-cpus") + 1] == "5"
    assert allowed[allowed.index("--other-cpus") + 1] == "2,3"
    assert bench.cpu_layout_args("partitioned", [0]) == ["--rt-priority", "40"]
    assert bench.cpu_layout_args("free", list(range(8))) == [
        "--rt-priority", "40", "--zenoh-priority", "30"]  # Zenoh's threads under the loops
    assert bench.cpu_layout_args("free", [0, 1]) == bench.cpu_layout_args("free", [0])
    with pytest.raises(ValueError, match="cpu layout"):
        bench.cpu_layout_args("isolated", [0, 1])
    # the slave's phase margin where both loops share a CPU, and nowhere else
    assert bench.slave_layout_args("partitioned", [0, 1]) == ["--phase-margin", "6e-05"]
    assert bench.slave_layout_args("partitioned", [0]) == []
    assert bench.slave_layout_args("free", [0, 1]) == []


def test_a_shorter_period_gets_a_spin_in_proportion(load_bench, tmp_path):
    """--period writes the period, and for a period under the configured 0.54 ms a spin of
    a tenth of it; the file passes the programs' own validation."""
    from haptic.common.config import load_config

    bench = load_bench("loop_bench")
    fast = load_config(bench.period_config(tmp_path, 0.00025))
    assert fast["model"]["sample_period_s"] == 0.00025
    assert fast["runner"]["spin_s"] == pytest.approx(2.5e-5)
    slow = load_config(bench.period_config(tmp_path, 0.001))
    assert slow["model"]["sample_period_s"] == 0.001
    assert slow["runner"]["spin_s"] == load_config()["runner"]["spin_s"]  # as shipped
    configured = load_config(bench.period_config(tmp_path, 0.00054))
    assert configured["runner"]["spin_s"] == load_config()["runner"]["spin_s"]


def test_the_default_layout_follows_the_nodes_and_the_period(load_bench):
    import argparse

    bench = load_bench("loop_bench")

    def layout(ts_s: float, **flags: object) -> str:
        args = argparse.Namespace(echo=False, master_cmd=None, slave_cmd=None)
        vars(args).update(flags)
        return bench.default_cpu_layout(args, ts_s)

    assert layout(0.00054) == "partitioned"
    assert layout(0.001) == "partitioned"
    assert layout(0.00025) == "free"  # both ticks do not fit one CPU's period
    assert layout(0.00054, echo=True) == "free"
    assert layout(0.00054, master_cmd="my-master") == "free"
