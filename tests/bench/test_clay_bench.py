"""The clay benchmark's device choice (``--device``): refused when it is not a Warp device
or not on this machine, else used for the Warp clay of both the timing and the physics runs.
The benchmark itself runs in .ci/run (``--quick --check``)."""

from __future__ import annotations

import numpy as np


def test_a_device_it_cannot_use_is_refused(load_bench, capsys, monkeypatch) -> None:
    import warp as wp

    bench = load_bench("clay_bench")
    assert bench.main(["--device", "gpu"]) == 2
    assert capsys.readouterr().err.strip().endswith(
        "config error: --device: must be auto, cpu, cuda or cuda:N (got 'gpu')")
    monkeypatch.setattr(wp, "get_cuda_device_count", lambda: 0)
    assert bench.main(["--device", "cuda:0"]) == 2
    assert "no CUDA device 'cuda:0' on this machine (0 found)" in capsys.readouterr().err


def test_the_device_reaches_the_timed_and_the_physics_clay(load_bench, monkeypatch) -> None:
    bench = load_bench("clay_bench")
    monkeypatch.setattr(bench, "GRIDS", ((1024, 256),))  # the grid its targets are read at
    monkeypatch.setattr(bench, "time_slave_steps", lambda node, steps: np.full(8, 1e-5))
    seen = []

    def physics(scenario, sample_period_s, device, save_dir):
        seen.append(device)
        return {"block_force_rel_error_max": 0.0, "removal_rel_error": 0.0,
                "conservation_rel_error": 0.0, "blocks": [{"ripple_rel_std": 0.0}]}

    monkeypatch.setattr(bench, "physics", physics)
    doc = bench.run(quick=True, save_dir=None, device="cpu")
    assert doc["device"] == "cpu" and seen == ["cpu"]
