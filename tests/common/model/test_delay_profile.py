"""Delay profiles: parsing, evaluation, and their use by the receive path's injection."""

from __future__ import annotations

import numpy as np
import pytest

from haptic.common.config import ConfigError, load_config, override
from haptic.common.model.delay_profile import DelayProfileError, parse_delay_profile
from haptic.common.wire.injection import Impairment, InjectionConfig
from haptic.common.wire.link_config import link_config_from
from haptic.lockstep.delay_line import source_schedule

MS = 1_000_000


def test_a_step_holds_each_delay_until_the_next_point() -> None:
    profile = parse_delay_profile("step 0:0.002 3:0.040")
    assert profile is not None
    assert profile.delay_s(0.0) == 0.002
    assert profile.delay_s(2.999) == 0.002
    assert profile.delay_s(3.0) == 0.040
    assert profile.delay_s(100.0) == 0.040
    assert profile.max_delay_s == 0.040 and profile.initial_delay_s == 0.002


def test_a_ramp_interpolates_and_holds_its_ends() -> None:
    profile = parse_delay_profile("linear 1:0.002 5:0.042")
    assert profile is not None
    assert profile.delay_s(0.0) == 0.002  # before the first point: the first delay
    assert profile.delay_s(3.0) == pytest.approx(0.022)
    assert profile.delay_s(9.0) == 0.042
    assert parse_delay_profile(profile.describe()) == profile


@pytest.mark.parametrize(("text", "words"), [
    ("ramp 0:0.1", "shape"),
    ("step 0:0.1 3", "time_s:delay_s"),
    ("step 0:x", "time_s:delay_s"),
    ("step 1:0.1 1:0.2", "increase"),
    ("step 0:-0.1", "delay"),
    ("step 0:11", "delay"),
    ("linear -1:0.1", "time"),
    ("step", "at least one"),
])
def test_bad_profiles_are_refused_with_the_reason(text: str, words: str) -> None:
    with pytest.raises(DelayProfileError, match=words):
        parse_delay_profile(text)


def test_the_empty_string_is_no_profile() -> None:
    assert parse_delay_profile("  ") is None


def test_config_key_is_validated_and_reaches_the_link_config() -> None:
    config = load_config()
    with pytest.raises(ConfigError, match=r"link\.slave\.injection\.delay_profile"):
        override(config, "link.slave.injection.delay_profile", "step 0:0.002 3")
    config = override(config, "link.slave.injection.delay_profile", "step 0:0.002 3:0.040")
    injection = link_config_from(config, "slave").injection
    assert injection.active and injection.max_extra_delay_s == pytest.approx(0.040)


def test_the_impairment_follows_the_profile_from_the_first_message() -> None:
    config = InjectionConfig(delay_s=0.001,
                             delay_profile=parse_delay_profile("step 0:0.002 3:0.040"))
    impairment = Impairment(config, np.random.default_rng(0))
    t0 = 1_700_000_000_000_000_000
    assert impairment.target_ns(t0) == t0 + 3 * MS  # 1 ms constant + 2 ms of the profile
    late = t0 + 2_999 * MS
    assert impairment.target_ns(late) == late + 3 * MS
    after = t0 + 3_000 * MS
    assert impairment.target_ns(after) == after + 41 * MS


def test_lockstep_schedule_steps_its_delay_at_the_profile_time() -> None:
    period = 0.001
    config = InjectionConfig(delay_profile=parse_delay_profile("step 0:0.002 0.1:0.040"))
    schedule = source_schedule(300, np.array([0]), 0, period, config,
                               np.random.default_rng(0))[:, 0]
    assert schedule[50] == 48  # 2 ms old
    assert schedule[250] == 210  # 40 ms old
    # messages sent from 0.1 s on arrive 38 ms later: the receiver keeps the last early one
    assert set(schedule[101:140]) == {99}
    assert schedule[140] == 100
