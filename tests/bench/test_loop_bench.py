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
    bench.print_table(result)
    table = capsys.readouterr().out
    assert f"node steps: {pacing['waited_ticks']} ticks waited, {pacing['caught_up_steps']} " \
        "caught up" in table
    assert table.count("node steps:") == 1


def test_cpu_layouts(load_bench):
    bench = load_bench("loop_bench")
    two = bench.cpu_layout_args("partitioned", [0, 1])
    assert two == ["--rt-priority", "40", "--loop-cpus", "1", "--other-cpus", "0",
                   "--spin-s", "0.00002"]
    allowed = bench.cpu_layout_args("partitioned", [2, 3, 5])  # e.g. under taskset
    assert allowed[allowed.index("--loop-cpus") + 1] == "5"
    assert allowed[allowed.index("--other-cpus") + 1] == "2,3"
    assert bench.cpu_layout_args("partitioned", [0]) == ["--rt-priority", "40"]
    assert bench.cpu_layout_args("free", list(range(8))) == ["--rt-priority", "40"]
    with pytest.raises(ValueError, match="cpu layout"):
        bench.cpu_layout_args("isolated", [0, 1])
    # the slave's phase margin where both loops share a CPU, and nowhere else
    assert bench.slave_layout_args("partitioned", [0, 1]) == ["--phase-margin", "6e-05"]
    assert bench.slave_layout_args("partitioned", [0]) == []
    assert bench.slave_layout_args("free", [0, 1]) == []
