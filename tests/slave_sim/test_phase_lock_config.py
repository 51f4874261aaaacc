"""The slave's [slave.phase_lock] table and its flags: validated at start, one-line errors.
The lock's lag is the runner's spin plus the margin (common/wire/phase_lock.py)."""

from __future__ import annotations

import subprocess
import sys

import pytest

from haptic.common.config import ConfigError, load_config, override
from haptic.slave_sim.program import phase_lock_from

PERIOD_S = 0.00054


def test_on_by_default_the_lag_is_the_spin_plus_the_margin():
    config = load_config()
    lock = phase_lock_from(config, PERIOD_S)
    assert lock is not None
    assert lock.settings.lag_s == pytest.approx(config["runner"]["spin_s"] + 30e-6)
    short_spin = override(config, "runner.spin_s", 20e-6)
    assert phase_lock_from(short_spin, PERIOD_S).settings.lag_s == pytest.approx(50e-6)


def test_off_gives_no_lock():
    config = override(load_config(), "slave.phase_lock.enabled", False)
    assert phase_lock_from(config, PERIOD_S) is None


def test_a_lag_of_a_period_or_more_names_the_key():
    config = override(load_config(), "slave.phase_lock.margin_s", PERIOD_S)
    with pytest.raises(ConfigError) as caught:
        phase_lock_from(config, PERIOD_S)
    assert caught.value.key == "slave.phase_lock.margin_s"


def test_a_file_giving_the_slave_table_keeps_the_default_lock(tmp_path):
    path = tmp_path / "slave.toml"
    path.write_text('[slave]\nscenario = "constant-rate"\nenvironment = "linear"\n'
                    'clay_impl = "numpy"\ndevice = "cpu"\n')
    assert load_config(path)["slave"]["phase_lock"] == {"enabled": True, "margin_s": 3e-05}
    path.write_text("[slave.phase_lock]\nenabled = false\n")
    assert load_config(path)["slave"]["phase_lock"] == {"enabled": False, "margin_s": 3e-05}
    path.write_text("[slave.phase_lock]\nmargin = 0.0001\n")
    with pytest.raises(ConfigError, match="slave.phase_lock.margin: unknown key"):
        load_config(path)


@pytest.mark.parametrize(("argv", "named"), [
    (["--phase-margin", "0.001"], "slave.phase_lock.margin_s: runner.spin_s + slave.phase_l"),
    (["--spin-s", "0.0006"], "runner.spin_s: runner.spin_s + slave.phase_lock.margin_s must"),
    (["--phase-margin", "-1"], "slave.phase_lock.margin_s"),
])
def test_bad_flags_exit_2_with_one_line(argv, named):
    done = subprocess.run([sys.executable, "-m", "haptic.slave_sim.cli", *argv,
                           "--duration", "1"], capture_output=True, text=True, timeout=120)
    assert done.returncode == 2
    errors = [line for line in done.stderr.splitlines() if line.startswith("config error")]
    assert len(errors) == 1 and named in errors[0]
    assert "stability" not in done.stderr  # refused before the analysis runs
