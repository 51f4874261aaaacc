"""`haptic-analyze`: JSON contract, plots, and one-line errors with exit status 2."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from haptic.common.analysis.cli import main

REQUIRED_KEYS = {"k", "delay_s", "stable", "delay_margin_s", "k_max", "k_max_delay_independent",
                 "eq30_satisfied", "eq30_worst_ratio"}


def test_json_has_the_contract_keys(capsys) -> None:
    assert main(["--k", "19", "--round-trip-delay", "0.005", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert REQUIRED_KEYS <= set(result)
    assert result["k"] == 19.0 and result["delay_s"] == 0.005
    assert result["stable"] is True
    assert 0.005 < result["delay_margin_s"] < 0.02
    assert set(result["axes"]) == {"x", "y"}


def test_sampled_margin_is_smaller(capsys) -> None:
    main(["--k", "19", "--json"])
    continuous = json.loads(capsys.readouterr().out)
    main(["--k", "19", "--json", "--sampled-analysis"])
    sampled = json.loads(capsys.readouterr().out)
    assert sampled["delay_margin_s"] < continuous["delay_margin_s"]
    assert continuous["delay_margin_s"] is not None


def test_stable_for_every_delay_reports_null_margin(capsys) -> None:
    main(["--k", "3", "--json"])
    assert json.loads(capsys.readouterr().out)["delay_margin_s"] is None


def test_plots_are_written(tmp_path: Path) -> None:
    assert main(["--k", "13", "--round-trip-delay", "0.02", "--out", str(tmp_path)]) == 0
    for name in ("nyquist.png", "compensators_bode.png", "stability_map.png"):
        assert (tmp_path / name).stat().st_size > 10_000


@pytest.mark.parametrize(
    ("text", "key"),
    [
        ("[model.ch1]\ngain_k = 1.0\nnum = [1.0, 0.0, 0.0, 0.0]\nden = [1.0, 10.0, 0.0]\n",
         "model.ch1.num"),
        ("[model]\nsample_period_s = 0.0\nposition_ratio_ah1 = [[1,0],[0,1]]\n"
         "force_ratio_ah2 = [[1,0],[0,1]]\n", "model.sample_period_s"),
        ("[model]\nsample_period_s = 0.001\nposition_ratio_ah1 = [[1,0],[0,1]]\n"
         "force_ratio_ah2 = [[1,0],[0,0]]\n", "model.force_ratio_ah2"),
        ("[analysis]\nmax_frequency_rad_s = -1.0\n", "analysis.max_frequency_rad_s"),
        ("[model.x]\ncolour = 'red'\n", "model.x.colour"),
    ],
)
def test_bad_config_is_one_line_and_exit_2(tmp_path: Path, text: str, key: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(text)
    run = subprocess.run([sys.executable, "-m", "haptic.common.analysis.cli", "--config",
                          str(path)], capture_output=True, text=True, timeout=120)
    assert run.returncode == 2
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and key in lines[0], run.stderr
    assert run.stdout == ""


def test_negative_delay_is_refused(capsys) -> None:
    with pytest.raises(SystemExit) as caught:
        main(["--round-trip-delay", "-0.1"])
    assert caught.value.code == 2
    assert "--round-trip-delay" in capsys.readouterr().err


def test_the_old_plot_option_is_refused_naming_out(capsys) -> None:
    """One vocabulary: a program's files go into ``--out DIR``; ``--plot`` says so."""
    with pytest.raises(SystemExit) as exit_info:
        main(["--plot", "somewhere"])
    assert exit_info.value.code == 2
    assert "--plot is now --out DIR" in capsys.readouterr().err
