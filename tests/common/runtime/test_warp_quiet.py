"""On a host without the NVIDIA CUDA driver the programs run Warp on its CPU device without
Warp's native warning about the missing driver on their stderr (common/runtime/warp_init.py)."""

from __future__ import annotations

import subprocess
import sys

import pytest


@pytest.mark.parametrize("argv", [
    ["haptic.master.cli", "--no-link", "--rig", "model", "--duration", "0.02"],
    ["haptic.slave_sim.scenario.cli", "--duration", "0.02", "--out", "OUT"],
    ["haptic.lockstep.cli", "run", "--environment", "linear", "--duration", "0.02",
     "--out", "OUT"],
])
def test_no_cuda_warning_on_stderr(argv: list[str], tmp_path) -> None:
    argv = [str(tmp_path) if part == "OUT" else part for part in argv]
    run = subprocess.run([sys.executable, "-m", *argv], capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 0, run.stderr
    assert "CUDA warning" not in run.stderr, run.stderr

