"""The Warp device of a clay sweep's lanes (lockstep/sweep.py ``SweepSettings.device``): its
checking, its choice per mode, and on a machine with CUDA the same verdicts as the CPU's."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from haptic.common.config import load_config
from haptic.common.model.teleop import model_from_config
from haptic.lockstep.cli import main
from haptic.lockstep.sweep import (
    SweepSettings,
    can_fork_workers,
    device_problem,
    lane_device,
    run_sweep,
)

HAS_CUDA = bool(wp.get_cuda_device_count())


@pytest.fixture(scope="module")
def model():
    return model_from_config(load_config())


def _clay_settings(device: str) -> SweepSettings:
    """Two gains either side of the clay loop's margin, at two delays each (1.5 s: the
    verdict's reference window starts at 1 s)."""
    return SweepSettings((1.0, 1.5), (0.004, 0.03), "clay", 1.5, reference_start_s=1.0,
                         device=device)


def test_device_names_are_checked(monkeypatch) -> None:
    assert device_problem("cpu") is None
    assert device_problem("auto") is None
    assert "got 'gpu'" in device_problem("gpu")
    assert "got 'cuda:x'" in device_problem("cuda:x")
    for odd in ("cuda:01", "cuda:00", "cuda:\u0660", "cuda:-1", "CUDA"):  # not Warp's names
        assert device_problem(odd) is not None, odd
    monkeypatch.setattr(wp, "get_cuda_device_count", lambda: 0)
    assert device_problem("cuda") == "no CUDA device 'cuda' on this machine (0 found)"
    assert device_problem("cuda", "linear") is None  # the linear mode has no clay
    assert device_problem("gpu", "linear") is not None  # but its form is still checked
    monkeypatch.setattr(wp, "get_cuda_device_count", lambda: 2)
    assert device_problem("cuda") is None
    assert device_problem("cuda:1") is None
    assert device_problem("cuda:2") == "no CUDA device 'cuda:2' on this machine (2 found)"


def test_lane_device_per_mode(monkeypatch) -> None:
    linear = SweepSettings((1.0,), (0.0,), "linear", device="cuda")
    assert lane_device(linear) == "cpu"  # the linear loop has no clay
    assert lane_device(_clay_settings("cuda:1")) == "cuda:1"
    monkeypatch.setattr(wp, "get_cuda_device_count", lambda: 0)
    assert lane_device(_clay_settings("auto")) == "cpu"
    monkeypatch.setattr(wp, "get_cuda_device_count", lambda: 1)
    assert lane_device(_clay_settings("auto")) == "cuda"


def test_sim_cli_rejects_a_device_it_cannot_use(capsys) -> None:
    with pytest.raises(SystemExit) as exited:
        main(["sweep", "--mode", "clay", "--device", "gpu"])
    assert exited.value.code == 2
    assert capsys.readouterr().err.strip().startswith("config error: --device: must be")
    if not HAS_CUDA:
        with pytest.raises(SystemExit) as exited:
            main(["sweep", "--mode", "clay", "--device", "cuda"])
        assert exited.value.code == 2
        assert "no CUDA device" in capsys.readouterr().err


def test_clay_sweep_on_cpu_says_so(model) -> None:
    result = run_sweep(model, _clay_settings("cpu"), workers=2)
    summary = result.summary()
    assert summary["device"] == "cpu"
    assert summary["workers"] == (2 if can_fork_workers() else 1)  # one part per gain
    assert summary["cells"] == 4
    assert summary["agree"] == 4  # one growing cell (k = 1.5 at 30 ms), three bounded
    assert result.growing.sum() == 1


@pytest.mark.skipif(not HAS_CUDA, reason="needs a CUDA device")
def test_clay_sweep_on_cuda_matches_cpu(model) -> None:
    """The clay lanes on CUDA give the CPU device's verdicts, in one process, and the same
    figures to within float64 rounding grown over the run."""
    cpu = run_sweep(model, _clay_settings("cpu"))
    cuda = run_sweep(model, _clay_settings("cuda"), workers=2)
    assert cuda.summary()["device"] == "cuda"
    assert cuda.summary()["workers"] == 1
    np.testing.assert_array_equal(cuda.growing, cpu.growing)
    np.testing.assert_allclose(cuda.peak_force_N, cpu.peak_force_N, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(cuda.energy_ratio, cpu.energy_ratio, rtol=1e-3, atol=1e-9)
