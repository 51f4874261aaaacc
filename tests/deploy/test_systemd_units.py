"""The shipped systemd units (deploy/systemd/): what the deployment needs is set, and
``systemd-analyze verify`` accepts them (skipped where it is not installed)."""

from __future__ import annotations

import configparser
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

UNITS = Path(__file__).resolve().parents[2] / "deploy" / "systemd"
NAMES = ("haptic-master", "haptic-slave", "haptic-router")
INSTALLED_BIN = "/opt/haptic/venv/bin/"


def unit(name: str) -> configparser.ConfigParser:
    parser = configparser.ConfigParser(strict=False, interpolation=None)
    parser.optionxform = str  # systemd keys are case sensitive
    parser.read(UNITS / f"{name}.service")
    return parser


@pytest.mark.parametrize("name", NAMES)
def test_unit_runs_its_program_as_haptic_with_a_restart_policy(name):
    service = unit(name)["Service"]
    assert service["User"] == "haptic" and service["Group"] == "haptic"
    assert service["Restart"] == "on-failure"
    assert service["ExecStart"].startswith(f"{INSTALLED_BIN}{name} ")
    assert "EnvironmentFile" in service
    if name != "haptic-router":  # the real-time loops
        assert service["CPUAffinity"] and int(service["Nice"]) < 0
        assert "IOSchedulingClass" in service
        assert "--no-status" in service["ExecStart"]
        assert f"client-{name.removeprefix('haptic-')}.json5" in service["ExecStart"]


@pytest.mark.parametrize("name", NAMES)
def test_unit_entry_point_exists(name):
    scripts = Path(sys.executable).parent
    assert (scripts / name).is_file(), f"console script {name} is not installed"


def test_systemd_analyze_verify(tmp_path):
    tool = shutil.which("systemd-analyze")
    if tool is None:
        pytest.skip("systemd-analyze is not installed")
    # point ExecStart at this environment's scripts: verify checks the binary exists
    scripts = str(Path(sys.executable).parent) + "/"
    for name in NAMES:
        text = (UNITS / f"{name}.service").read_text().replace(INSTALLED_BIN, scripts)
        (tmp_path / f"{name}.service").write_text(text)
    result = subprocess.run([tool, "verify", *sorted(map(str, tmp_path.glob("*.service")))],
                            capture_output=True, text=True, timeout=60)
    report = result.stdout + result.stderr
    assert result.returncode == 0, report
    assert "ignoring" not in report.lower() and "unknown" not in report.lower(), report
