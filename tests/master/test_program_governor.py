"""haptic-master's governor set-up: off by default, the table printed, a delay profile
beyond every gain's margin refused (exit 3) unless --allow-unstable, lower_k refused on a
design that is not linear in k."""

from __future__ import annotations

import argparse
import io
import math

import pytest

from haptic.common.analysis.preflight import EXIT_UNSTABLE, round_trip_delay_s
from haptic.common.config import ConfigError, override
from haptic.common.model.teleop import model_from_config
from haptic.master.program_governor import start_governor


def _args(**values) -> argparse.Namespace:
    return argparse.Namespace(**{"governor": None, "allow_unstable": False, **values})


def test_off_by_default(paper_config) -> None:
    model = model_from_config(paper_config)
    assert start_governor(paper_config, _args(), model) == (None, None)


def test_a_profile_beyond_every_margin_is_refused_unless_allowed(paper_config) -> None:
    config = override(paper_config, "link.master.injection.delay_profile",
                      "step 0:0.002 3:0.100")
    config = override(config, "governor.min_gain_k", 12.0)  # table: k 13 and 12 only
    model = model_from_config(config).with_gain(13.0)
    stream = io.StringIO()
    governor, refused = start_governor(config, _args(governor=True), model, stream=stream)
    assert governor is None and refused == EXIT_UNSTABLE
    lines = stream.getvalue().strip().splitlines()
    assert "k 13: 14.3 ms" in lines[0] and "--allow-unstable" in lines[-1]
    governor, refused = start_governor(config, _args(governor=True, allow_unstable=True),
                                       model, stream=io.StringIO())
    assert refused is None and [e.k for e in governor.table.entries] == [13.0, 12.0]


def test_the_analysis_of_a_governed_run_takes_the_profile_start(paper_config) -> None:
    config = override(paper_config, "link.master.injection.delay_profile",
                      "step 0:0.002 3:0.040")
    assert round_trip_delay_s(config, 0.0, profile="max") == pytest.approx(0.040)
    assert round_trip_delay_s(config, 0.0, profile="initial") == pytest.approx(0.002)


def test_lower_k_needs_a_design_linear_in_k(paper_config) -> None:
    # a compliance that rolls off as fast as Gh (relative degree 2), so the design synthesises
    config = override(paper_config, "model.x.handle_compliance_sh_num", [1e-4])
    config = override(config, "model.x.handle_compliance_sh_den", [1e-4, 0.02, 1.0])
    with pytest.raises(ConfigError, match=r"governor\.action"):
        start_governor(config, _args(governor=True), model_from_config(config),
                       stream=io.StringIO())


def test_an_echo_of_no_handle_message_sent_is_counted_and_never_a_round_trip() -> None:
    """A tool message's echoed handle send time must lie between this master's first and
    newest sent message: a future echo read as a round trip of 0 kept the nominal gain
    whatever the delay, and an echo of 1 ns invented a huge one."""
    from types import SimpleNamespace

    from haptic.common.config import load_config
    from haptic.master.margin_governor import governor_for
    from haptic.master.program_governor import governor_step

    config = override(load_config(), "governor.enabled", True)
    governor = governor_for(model_from_config(config), config)
    t0 = 1_700_000_000_000_000_000
    link = SimpleNamespace(first_sent_ns=t0, last_sent_ns=t0 + 10_000_000,
                           last_poll_ns=t0 + 12_000_000, latest=None)
    for echo_ns in (t0 + 10**12, 1, t0 - 1):
        link.latest = SimpleNamespace(echo_send_time_ns=echo_ns)
        for tick in range(3):  # the same message on every tick: counted once
            governor_step(governor, link.latest, link.first_sent_ns, link.last_sent_ns,
                          link.last_poll_ns, tick * 1e-3)
        assert math.isnan(governor.rtt_s) and governor.max_rtt_s == 0.0  # no round trip yet
    assert governor.invalid_echoes == 3
    link.latest = SimpleNamespace(echo_send_time_ns=t0 + 4_000_000)  # sent: 8 ms ago
    governor_step(governor, link.latest, link.first_sent_ns, link.last_sent_ns,
                  link.last_poll_ns, 0.01)
    assert governor.rtt_s == pytest.approx(0.008)
    assert governor.invalid_echoes == 3 and governor.summary()["governor_invalid_echoes"] == 3
