"""The pre-flight stability check of the programs."""

from __future__ import annotations

import argparse
import io

import pytest

from haptic.common.analysis.preflight import (
    EXIT_UNSTABLE,
    add_preflight_options,
    check_stability,
    round_trip_delay_s,
    run_preflight,
)
from haptic.common.config import load_config, override


def _args(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    add_preflight_options(parser)
    return parser.parse_args(list(argv))


def test_round_trip_adds_both_injections_and_twice_the_link() -> None:
    config = override(load_config(), "link.master.injection.delay_s", 0.004)
    config = override(config, "link.slave.injection.delay_s", 0.006)
    config = override(config, "link.slave.injection.jitter_s", 0.001)
    assert round_trip_delay_s(config, 0.0005) == pytest.approx(0.004 + 0.006 + 0.001 + 0.001)


def test_verdicts_follow_the_delay_margin() -> None:
    config = override(load_config(), "model.ch1.gain_k", 19.0)
    short = check_stability(config, 0.001)
    long = check_stability(config, 0.02)
    assert short.stable and not long.stable
    assert short.delay_margin_s == long.delay_margin_s
    assert 0.001 < short.delay_margin_s < 0.02
    assert long.margin_left_s < 0.0 < short.margin_left_s
    assert check_stability(load_config(), 0.02).delay_margin_s is None  # k = 1


def test_refusal_names_allow_unstable_and_the_flag_overrides_it() -> None:
    config = override(load_config(), "model.ch1.gain_k", 19.0)
    config = override(config, "link.slave.injection.delay_s", 0.02)
    stream = io.StringIO()
    result, status = run_preflight(config, _args(), "prog", stream)
    assert status == EXIT_UNSTABLE and not result.stable
    lines = stream.getvalue().splitlines()
    assert "UNSTABLE" in lines[0]
    assert len(lines) == 2 and "--allow-unstable" in lines[1]
    stream = io.StringIO()
    result, status = run_preflight(config, _args("--allow-unstable"), "prog", stream)
    assert status is None and "anyway" in stream.getvalue()


def test_sampled_analysis_is_selectable() -> None:
    result, status = run_preflight(load_config(), _args("--sampled-analysis"), "prog",
                                   io.StringIO())
    assert result.sampled and result.stable and status is None
    assert "sampled-data" in result.describe()


def test_peer_delay_replaces_the_other_sides_configured_delay() -> None:
    config = override(load_config(), "link.master.injection.delay_s", 0.004)
    config = override(config, "link.slave.injection.delay_s", 0.01)
    # the slave's program: its own 10 ms plus the master's, given as --peer-one-way-delay 10 ms
    assert round_trip_delay_s(config, 0.0, "slave", 0.01) == pytest.approx(0.02)
    assert round_trip_delay_s(config, 0.0, "master", 0.01) == pytest.approx(0.014)
    assert round_trip_delay_s(config, 0.0) == pytest.approx(0.014)
    config = override(config, "model.ch1.gain_k", 13.0)
    _, status = run_preflight(config, _args("--peer-one-way-delay", "0.01"), "prog", io.StringIO(),
                              side="slave")
    assert status == EXIT_UNSTABLE  # 21 ms round trip against a 17.9 ms margin at k = 13


def test_bad_preflight_flags_are_config_errors() -> None:
    from haptic.common.config import ConfigError

    with pytest.raises(ConfigError) as caught:
        run_preflight(load_config(), _args("--peer-one-way-delay", "-1"), "prog",
                      io.StringIO(), "slave")
    assert caught.value.key == "--peer-one-way-delay"


def test_the_clay_environment_changes_the_verdict() -> None:
    """With the clay's linearisation Tt = 100 s, k = 13 is unstable at any delay (what the
    networked sessions show), while the paper's Tt keeps it stable up to 17.9 ms."""
    config = override(load_config(), "model.ch1.gain_k", 13.0)
    stream = io.StringIO()
    result, status = run_preflight(config, _args("--analysis-environment", "clay"), "prog",
                                   stream, "slave", clay_damping_N_s_per_m=100.0)
    assert status == EXIT_UNSTABLE and "even without delay" in stream.getvalue()
    assert "Tt = 100 s (clay)" in stream.getvalue()
    result, status = run_preflight(config, _args(), "prog", io.StringIO(), "slave")
    assert status is None and result.delay_margin_s > 0.017
