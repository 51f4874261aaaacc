"""Configuration loading and validation: every bad key is named, nothing passes silently."""

from __future__ import annotations

from pathlib import Path

import pytest

from haptic.common.config import ConfigError, load_config, override, to_toml
from haptic.common.model.teleop import model_from_config


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "run.toml"
    path.write_text(text)
    return path


def test_defaults_are_the_papers_values(paper_config: dict) -> None:
    model = paper_config["model"]
    assert model["sample_period_s"] == pytest.approx(0.54e-3)
    assert model["ch1"]["den"] == [1.0, 10.0, 0.0]
    assert model["x"]["handle_actuator_gh_den"] == [0.005, 0.4, 18.0, 1.0]
    assert model["y"]["handle_actuator_gh_num"] == [8.0, 1.0]
    assert model["x"]["operator_impedance_th"] == [0.25, 2.0, 6.0]
    assert model["x"]["tool_damping_N_s_per_m"] == 100.0


def test_a_sub_table_alone_keeps_the_parent_defaults(tmp_path: Path) -> None:
    config = load_config(write(tmp_path, "[model.ch1]\ngain_k = 3.0\nnum = [1.0]\n"
                                         "den = [1.0, 10.0, 0.0]\n"))
    assert config["model"]["ch1"]["gain_k"] == 3.0
    assert config["model"]["sample_period_s"] == pytest.approx(0.54e-3)


@pytest.mark.parametrize(
    ("text", "key", "message"),
    [
        ("[model.ch1]\ngain_k = 3.0\nnum = [1.0]\nden = [1.0, 10.0, 0.0]\nextra = 1\n",
         "model.ch1.extra", "unknown key"),
        ("[model.ch1]\ngain_k = 3.0\nnum = [1.0]\n", "model.ch1.den",
         "missing key (set together with model.ch1.num)"),
        ("[model.x]\ntool_compliance_st_den = [1.0, 2.0]\n", "model.x.tool_compliance_st_num",
         "missing key (set together with model.x.tool_compliance_st_den)"),
        ("[runner]\nspin_seconds = 0.0001\n", "runner.spin_seconds", "unknown key"),
        ("[nonsense]\n", "nonsense", "unknown key"),
        ("[model]\nsample_period_s = -0.001\nposition_ratio_ah1 = [[1,0],[0,1]]\n"
         "force_ratio_ah2 = [[1,0],[0,1]]\n", "model.sample_period_s", "must be >= 1e-05"),
        ("[model]\nsample_period_s = 0.0\nposition_ratio_ah1 = [[1,0],[0,1]]\n"
         "force_ratio_ah2 = [[1,0],[0,1]]\n", "model.sample_period_s", "must be >= 1e-05"),
        ("[model]\nsample_period_s = 1e300\n", "model.sample_period_s", "must be <= 0.1"),
        ("[slave]\nscenario = \"a\\u0000b.toml\"\n", "slave.scenario", "control characters"),
        ("[slave]\nscenario = \"a\\nb.toml\"\n", "slave.scenario", "control characters"),
        ("[analysis]\nround_trip_delay_s = 1e300\n", "analysis.round_trip_delay_s",
         "must be <= 10"),
        ("[analysis]\nmax_frequency_rad_s = 1e-300\n", "analysis.max_frequency_rad_s",
         "must be >= 1"),
        ("[governor]\nurgent_factor = 0.5\n", "governor.urgent_factor",
         "must be >= governor.safety_factor"),
        ("[master.can]\ndbc_file = \"nosuch.dbc\"\n", "master.can.dbc_file", "no such file"),
        ("[master.can]\nx_eds_file = \"x\"\n", "master.can.x_eds_file", ".eds or .dcf file"),
        ("[master.can]\ny_eds_file = \"nosuch.dcf\"\n", "master.can.y_eds_file", "no such file"),
        ("[model]\nsample_period_s = 0.001\nposition_ratio_ah1 = [[1,0],[0,0]]\n"
         "force_ratio_ah2 = [[1,0],[0,1]]\n", "model.position_ratio_ah1", "singular"),
        ("[model]\nsample_period_s = 0.001\nposition_ratio_ah1 = [[1,0.5],[0,1]]\n"
         "force_ratio_ah2 = [[1,0],[0,1]]\n", "model.position_ratio_ah1", "diagonal"),
        ("[model]\nsample_period_s = 'fast'\nposition_ratio_ah1 = [[1,0],[0,1]]\n"
         "force_ratio_ah2 = [[1,0],[0,1]]\n", "model.sample_period_s", "finite number"),
        ("[analysis]\nround_trip_delay_s = nan\nmax_frequency_rad_s = 1e4\nmax_delay_s = 1.0\n"
         "max_gain_k = 100.0\n", "analysis.round_trip_delay_s", "finite"),
        ("[model.ch1]\ngain_k = 3.0\nnum = [1.0]\nden = [0.0, 0.0]\n", "model.ch1.den",
         "zero polynomial"),
        ("model = [", "", "not valid TOML"),
    ],
)
def test_bad_files_name_the_key(tmp_path: Path, text: str, key: str, message: str) -> None:
    with pytest.raises(ConfigError) as caught:
        load_config(write(tmp_path, text))
    assert caught.value.key == key
    assert message in str(caught.value)


def test_a_file_sets_any_subset_of_a_tables_keys(tmp_path: Path, paper_config: dict) -> None:
    config = load_config(write(tmp_path, "[runner]\nspin_s = 0.0002\n\n[model.ch1]\n"
                                         "gain_k = 13.0\n\n[link.watchdog]\n"
                                         "max_message_age_s = 0.05\n"))
    assert config["runner"]["spin_s"] == 0.0002
    assert config["model"]["ch1"]["gain_k"] == 13.0
    assert config["link"]["watchdog"]["max_message_age_s"] == 0.05
    # every other key keeps its default, in the same tables and elsewhere
    for table, key in (("runner", "spin_s"), ("model", "ch1"), ("link", "watchdog")):
        changed = dict(config[table])
        default = dict(paper_config[table])
        changed.pop(key)
        default.pop(key)
        assert changed == default
    assert config["model"]["ch1"]["num"] == paper_config["model"]["ch1"]["num"]
    assert config["link"]["watchdog"]["resync_messages"] == \
        paper_config["link"]["watchdog"]["resync_messages"]
    assert config["slave"] == paper_config["slave"]


def test_print_config_shows_the_merged_configuration(tmp_path: Path, capsys) -> None:
    from haptic.common.analysis.cli import main

    path = write(tmp_path, "[model.ch1]\ngain_k = 7.5\n")
    assert main(["--config", str(path), "--print-config"]) == 0
    printed = capsys.readouterr().out
    again = write(tmp_path, printed)
    assert load_config(again) == load_config(path)
    assert load_config(again)["model"]["ch1"]["gain_k"] == 7.5


def test_improper_ch1_is_refused_naming_the_key(tmp_path: Path) -> None:
    config = load_config(write(tmp_path, "[model.ch1]\ngain_k = 1.0\nnum = [1.0, 0.0, 0.0, 0.0]\n"
                                         "den = [1.0, 10.0, 0.0]\n"))
    with pytest.raises(ConfigError) as caught:
        model_from_config(config)
    assert caught.value.key == "model.ch1.num"
    assert "improper" in str(caught.value)


def test_missing_file_is_a_config_error(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="cannot read config file"):
        load_config(tmp_path / "absent.toml")


def test_override_validates_the_value(paper_config: dict) -> None:
    changed = override(paper_config, "model.ch1.gain_k", 13)
    assert changed["model"]["ch1"]["gain_k"] == 13.0
    assert paper_config["model"]["ch1"]["gain_k"] == 1.0
    with pytest.raises(ConfigError, match="model.ch1.gain_k"):
        override(paper_config, "model.ch1.gain_k", -1.0)
    with pytest.raises(ConfigError, match="unknown key"):
        override(paper_config, "model.ch1.gain", 1.0)


def test_to_toml_gives_another_process_the_same_configuration(paper_config: dict,
                                                               tmp_path: Path) -> None:
    changed = override(paper_config, "master.sim.operator", 'regulate:fx=3.6,onset=0.2')
    changed = override(changed, "model.sample_period_s", 1e-05)
    changed = override(changed, "master.sim.emulator.channel", 'dir "quoted" \\ \u00e9')
    changed = override(changed, "model.ch1.gain_k", 13)
    for config in (paper_config, changed):
        assert load_config(write(tmp_path, to_toml(config))) == config
    assert load_config(write(tmp_path, to_toml(changed))) != paper_config


@pytest.mark.parametrize(("text", "key", "message"), [
    ("[model.ch1]\nnum = [0.0]\nden = [1.0, 10.0, 0.0]\n", "model.ch1.num", "must not be zero"),
    ("[model.x]\nhandle_compliance_sh_num = [1.0]\nhandle_compliance_sh_den = [1.0]\n",
     "model.x", "Ct1 is improper"),
    ("[model.y]\ntool_mass_kg = 0.0\n", "model.y.tool_mass_kg",
     "Pt = Tt Gt/(1 - Tt St) is improper"),
    ("[model.x]\ntool_damping_N_s_per_m = 1e300\n", "model.x", "Pt = Tt Gt/(1 - Tt St)"),
])
def test_a_model_no_program_can_run_names_its_table(tmp_path: Path, text: str, key: str,
                                                    message: str) -> None:
    """A model that passes the keys' own checks but that no program can run (its
    compensators do not synthesise, or a plant is improper) is a ConfigError naming the axis
    table, as every program's start needs, not a traceback from the first synthesis."""
    with pytest.raises(ConfigError) as caught:
        model_from_config(load_config(write(tmp_path, text)))
    assert caught.value.key == key
    assert message in str(caught.value)


def test_an_emulator_interface_python_can_does_not_have_names_its_key(tmp_path: Path) -> None:
    """Checked with the master's settings (reading a configuration loads no CAN stack:
    tests/common/test_layers.py), before any process starts."""
    from haptic.master.settings import master_settings

    config = load_config(write(tmp_path, "[master.sim.emulator]\ninterface = \"nosuch\"\n"))
    with pytest.raises(ConfigError) as caught:
        master_settings(config)
    assert caught.value.key == "master.sim.emulator.interface"
    assert "not a python-can interface" in str(caught.value)
