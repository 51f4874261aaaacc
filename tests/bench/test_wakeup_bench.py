"""bench/wakeup_bench.py briefly: its cases and JSON shape, the echo process ended and reaped,
the CPU latency request held or its refusal said. No figure is asserted (timing is the
benchmark's output, not a test)."""

from __future__ import annotations

import json
import os

import pytest


def _children() -> set[int]:
    """This process's child PIDs (Linux)."""
    path = f"/proc/{os.getpid()}/task/{os.getpid()}/children"
    with open(path) as children:
        return {int(pid) for pid in children.read().split()}


@pytest.mark.skipif(not hasattr(os, "sched_getaffinity"), reason="Linux CPU affinity")
def test_cases_json_and_the_echo_process_reaped(load_bench, capsys):
    bench = load_bench("wakeup_bench")
    affinity = os.sched_getaffinity(0)
    children = _children()
    assert bench.main(["--round-trips", "50", "--period", "0.001", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert os.sched_getaffinity(0) == affinity  # this process's CPUs given back
    assert _children() == children  # every echo process ended and reaped
    expected = {"same_cpu", "same_cpu_paced"} | (
        {"cross_cpu", "cross_cpu_paced"} if len(affinity) >= 2 else set())
    assert set(result["as_is"]) == expected
    for case in result["as_is"].values():
        assert case["round_trips"] in (50, 200)  # paced: at least 200
        assert 0 < case["round_trip_p50_s"] <= case["round_trip_p99_s"]
        assert case["cpu_per_wakeup_s"] >= 0
    requested = result["requested"]
    if "warning" in requested:  # no write access to the PM QoS device here
        assert "refused" in requested["warning"]
    else:
        assert requested["cpu_latency_limit_us"] == 0
        assert expected <= set(requested)
    assert result["cpu_model"]


def test_no_request_measures_as_they_are_only(load_bench):
    bench = load_bench("wakeup_bench")
    result = bench.measure(20, 0.001, cpu_latency_limit_us=-1)
    assert "requested" not in result
    lines = bench.format_result(result)
    assert lines[1] == " idle states as they are:"
    assert not any("CPU latency limit" in line for line in lines)


def test_bad_arguments_exit_2(load_bench):
    bench = load_bench("wakeup_bench")
    with pytest.raises(SystemExit) as exited:
        bench.main(["--cpu-latency-us", "-2"])
    assert exited.value.code == 2
