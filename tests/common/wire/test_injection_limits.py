"""The link's injected delay, jitter and loss (common/wire/injection.py) to the exact value:
config validation at each field's bounds, ``active``, ``max_extra_delay_s``, the delivery
target of a message for a given seed, the order of the random draws, and the Gilbert-Elliott
loss in each state (checked against binomial bounds, seeded)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.stats import binom

from haptic.common.model.delay_profile import parse_delay_profile
from haptic.common.wire.injection import Impairment, InjectionConfig

T0 = 1_700_000_000_000_000_000  # a send time as the programs stamp it: ns since 1970
PROBABILITIES = ("loss_probability", "burst_enter_probability", "burst_loss_probability")
BELOW_ZERO = -5e-324  # the largest negative float
ABOVE_ONE = math.nextafter(1.0, 2.0)


class _Draws:
    """The documented draws of a seed: uniforms (loss and uniform jitter) taken from the
    generator 1024 at a time, normal and exponential jitter straight from the generator."""

    def __init__(self, seed: int) -> None:
        self.generator = np.random.default_rng(seed)
        self._block: list[float] = []

    def uniform(self) -> float:
        if not self._block:
            self._block = self.generator.random(1024).tolist()[::-1]
        return self._block.pop()


def _uniforms(seed: int, n: int) -> np.ndarray:
    return np.random.default_rng(seed).random(n)


# --- the configuration ---------------------------------------------------------------------


def test_defaults_inject_nothing_and_keep_order() -> None:
    """The defaults: no delay, jitter or loss, uniform jitter, order kept, bursts fully lossy."""
    config = InjectionConfig()
    assert (config.delay_s, config.jitter_s, config.jitter_distribution) == (0.0, 0.0, "uniform")
    assert config.preserve_order is True
    assert (config.loss_probability, config.burst_enter_probability) == (0.0, 0.0)
    assert (config.burst_exit_probability, config.burst_loss_probability) == (1.0, 1.0)
    assert config.delay_profile is None


def test_every_field_accepts_its_bounds() -> None:
    """Each field's own bounds are accepted: times 0, probabilities 0 and 1, exit just above 0."""
    InjectionConfig(delay_s=0.0, jitter_s=0.0, loss_probability=0.0,
                    burst_enter_probability=0.0, burst_loss_probability=0.0,
                    burst_exit_probability=5e-324)
    InjectionConfig(loss_probability=1.0, burst_enter_probability=1.0,
                    burst_loss_probability=1.0, burst_exit_probability=1.0)
    for distribution in ("uniform", "normal", "exponential"):
        assert InjectionConfig(jitter_distribution=distribution).jitter_distribution == distribution


@pytest.mark.parametrize(("field", "value", "message"), [
    ("delay_s", BELOW_ZERO, "delay_s must be finite and >= 0 (got -5e-324)"),
    ("delay_s", math.nan, "delay_s must be finite and >= 0 (got nan)"),
    ("jitter_s", BELOW_ZERO, "jitter_s must be finite and >= 0 (got -5e-324)"),
    ("jitter_s", math.nan, "jitter_s must be finite and >= 0 (got nan)"),
    ("delay_s", math.inf, "delay_s must be finite and >= 0 (got inf)"),
    ("jitter_s", math.inf, "jitter_s must be finite and >= 0 (got inf)"),
    ("jitter_distribution", "pareto",
     "jitter_distribution must be one of uniform, normal, exponential (got 'pareto')"),
    ("jitter_distribution", "Uniform",
     "jitter_distribution must be one of uniform, normal, exponential (got 'Uniform')"),
    *((name, value, f"{name} must be in [0, 1] (got {value})")
      for name in PROBABILITIES for value in (BELOW_ZERO, ABOVE_ONE, math.nan)),
    ("burst_exit_probability", 0.0, "burst_exit_probability must be in (0, 1] (got 0.0)"),
    ("burst_exit_probability", -0.0, "burst_exit_probability must be in (0, 1] (got -0.0)"),
    ("burst_exit_probability", ABOVE_ONE,
     f"burst_exit_probability must be in (0, 1] (got {ABOVE_ONE})"),
    ("burst_exit_probability", math.nan, "burst_exit_probability must be in (0, 1] (got nan)"),
])
def test_each_field_refuses_a_value_just_outside_its_bounds(field, value, message) -> None:
    """A value just outside a field's bounds (or NaN) raises, the message naming field and value."""
    with pytest.raises(ValueError) as raised:
        InjectionConfig(**{field: value})
    assert str(raised.value) == message


def test_config_is_frozen_and_hashable() -> None:
    """A config cannot be changed after validation, and equal configs hash alike."""
    config = InjectionConfig(delay_s=0.01)
    with pytest.raises(dataclasses.FrozenInstanceError):
        config.delay_s = -1.0  # type: ignore[misc]
    assert hash(config) == hash(InjectionConfig(delay_s=0.01))


@pytest.mark.parametrize(("changes", "active"), [
    ({}, False),
    ({"preserve_order": False, "jitter_distribution": "normal"}, False),
    ({"delay_s": 5e-324}, True),
    ({"jitter_s": 5e-324}, True),
    ({"loss_probability": 5e-324}, True),
    ({"delay_profile": "step 0:0"}, False),
    ({"delay_profile": "step 0:0 1:0"}, False),
    ({"delay_profile": "step 0:0 1:0.001"}, True),
    ({"burst_enter_probability": 5e-324}, True),  # burst loss defaults to 1
    ({"burst_enter_probability": 1.0, "burst_loss_probability": 0.0}, False),
    ({"burst_enter_probability": 0.0, "burst_loss_probability": 1.0}, False),
    ({"burst_enter_probability": 0.0, "burst_exit_probability": 0.5}, False),
    ({"burst_enter_probability": 0.1, "burst_loss_probability": 5e-324}, True),
])
def test_active_exactly_when_something_is_injected(changes, active) -> None:
    """``active`` is true iff a delay, profile delay, jitter, loss or lossy burst can happen."""
    if "delay_profile" in changes:
        changes = {**changes, "delay_profile": parse_delay_profile(changes["delay_profile"])}
    assert InjectionConfig(**changes).active is active


def test_max_extra_delay_is_delay_plus_profile_maximum_plus_jitter() -> None:
    """``max_extra_delay_s`` = delay_s + the profile's largest delay (anywhere) + jitter_s."""
    assert InjectionConfig().max_extra_delay_s == 0.0
    assert InjectionConfig(delay_s=0.01, jitter_s=0.005).max_extra_delay_s == 0.01 + 0.005
    profile = parse_delay_profile("linear 0:0.002 5:0.040 6:0.010")
    config = InjectionConfig(delay_s=0.01, jitter_s=0.005, delay_profile=profile)
    assert config.max_extra_delay_s == 0.01 + 0.040 + 0.005
    assert InjectionConfig(delay_profile=profile).max_extra_delay_s == 0.040


# --- the delivery target -------------------------------------------------------------------


@pytest.mark.parametrize("send_ns", [0, 1, T0])
def test_without_injection_the_target_is_the_send_time(send_ns) -> None:
    """Nothing injected: the target is the send time itself, also at t = 0."""
    impairment = Impairment(InjectionConfig(), np.random.default_rng(0))
    assert impairment.target_ns(send_ns) == send_ns
    assert not impairment.lost()


@pytest.mark.parametrize(("delay_s", "extra_ns"), [
    (0.0015, 1_500_000), (0.02, 20_000_000), (2.5, 2_500_000_000), (10.0, 10_000_000_000),
    (2.4e-9, 2), (2.6e-9, 3),
])
def test_constant_delay_is_added_to_the_ns(delay_s, extra_ns) -> None:
    """The constant delay is added rounded to the nearest ns, for every message alike."""
    impairment = Impairment(InjectionConfig(delay_s=delay_s), np.random.default_rng(0))
    assert [impairment.target_ns(T0 + k) for k in range(3)] == [T0 + k + extra_ns
                                                                for k in range(3)]


def test_profile_delay_counts_from_the_first_message_to_the_ns() -> None:
    """A profile's delay is taken at (send - first send) s and added rounded to the ns."""
    profile = parse_delay_profile("linear 0:0 1:1 2:2.5")
    impairment = Impairment(InjectionConfig(delay_s=0.001, delay_profile=profile),
                            np.random.default_rng(0))
    assert impairment.profile_origin_ns is None
    first = T0 + 123
    assert impairment.target_ns(first) == first + 1_000_000
    assert impairment.profile_origin_ns == first
    quarter = first + 250_000_000
    assert impairment.target_ns(quarter) == quarter + 1_000_000 + 250_000_000
    late = first + 3_000_000_000
    assert impairment.target_ns(late) == late + 1_000_000 + 2_500_000_000
    assert impairment.profile_origin_ns == first


def test_preserve_order_makes_the_target_a_running_maximum() -> None:
    """With order kept (the default) each target is the running maximum of the free targets."""
    sends = T0 + np.arange(3000) * 1_000_000
    free = Impairment(InjectionConfig(jitter_s=0.01, preserve_order=False),
                      np.random.default_rng(4))
    targets = np.array([free.target_ns(int(s)) for s in sends])
    assert np.any(np.diff(targets) < 0)  # the jitter alone reorders
    kept = Impairment(InjectionConfig(jitter_s=0.01), np.random.default_rng(4))
    ordered = np.array([kept.target_ns(int(s)) for s in sends])
    assert np.array_equal(ordered, np.maximum.accumulate(targets))
    assert np.any(ordered > targets)  # some messages are held back


def test_preserve_order_holds_back_a_message_sent_earlier() -> None:
    """A message sent before the previous one is given at least the previous target."""
    impairment = Impairment(InjectionConfig(delay_s=0.002), np.random.default_rng(0))
    assert impairment.target_ns(T0 + 1000) == T0 + 1000 + 2_000_000
    assert impairment.target_ns(T0) == T0 + 1000 + 2_000_000
    free = Impairment(InjectionConfig(delay_s=0.002, preserve_order=False),
                      np.random.default_rng(0))
    assert free.target_ns(T0 + 1000) == T0 + 1000 + 2_000_000
    assert free.target_ns(T0) == T0 + 2_000_000


# --- the jitter draws ----------------------------------------------------------------------


@pytest.mark.parametrize("jitter_s", [0.002, 0.25, 1.0])
def test_uniform_jitter_is_the_seeds_uniforms_times_the_bound(jitter_s) -> None:
    """Uniform jitter of message k is int(u_k * jitter_s in ns), u_k the seed's k-th uniform."""
    n = 2500  # more than two blocks of uniforms
    impairment = Impairment(InjectionConfig(jitter_s=jitter_s, preserve_order=False),
                            np.random.default_rng(11))
    got = [impairment.target_ns(T0) - T0 for _ in range(n)]
    expected = (_uniforms(11, n) * (jitter_s * 1e9)).astype(np.int64)
    assert got == expected.tolist()


@pytest.mark.parametrize("jitter_s", [0.004, 3e-9, 1e-9])
def test_normal_jitter_is_centred_with_a_sixth_of_the_bound_and_clipped(jitter_s) -> None:
    """Normal jitter: int of jitter x (0.5 + z / 6) clipped to [0, jitter], z the seed's normals."""
    n = 4000
    impairment = Impairment(InjectionConfig(jitter_s=jitter_s, jitter_distribution="normal",
                                            preserve_order=False), np.random.default_rng(12))
    got = np.array([impairment.target_ns(T0) - T0 for _ in range(n)])
    bound = jitter_s * 1e9
    z = np.random.default_rng(12).standard_normal(n)
    expected = np.clip(bound * (0.5 + z / 6.0), 0.0, bound).astype(np.int64)
    assert np.array_equal(got, expected)
    assert got.min() == 0 and got.max() == int(bound)  # both clips are reached


@pytest.mark.parametrize("jitter_s", [0.004, 1e-9])
def test_exponential_jitter_has_a_fifth_of_the_bound_as_mean_and_is_clipped(jitter_s) -> None:
    """Exponential jitter: int of (jitter / 5) x the seed's standard exponentials, <= jitter."""
    n = 4000
    impairment = Impairment(InjectionConfig(jitter_s=jitter_s,
                                            jitter_distribution="exponential",
                                            preserve_order=False), np.random.default_rng(13))
    got = np.array([impairment.target_ns(T0) - T0 for _ in range(n)])
    bound = jitter_s * 1e9
    e = np.random.default_rng(13).standard_exponential(n)
    expected = np.minimum(bound / 5.0 * e, bound).astype(np.int64)
    assert np.array_equal(got, expected)
    assert got.max() == int(bound)  # the clip is reached


@pytest.mark.parametrize("distribution", ["uniform", "normal", "exponential"])
def test_loss_and_jitter_draws_interleave_in_the_documented_order(distribution) -> None:
    """Per message: the loss uniform, then the jitter draw; uniforms come 1024 at a time."""
    config = InjectionConfig(jitter_s=0.003, jitter_distribution=distribution,
                             loss_probability=0.5, preserve_order=False)
    impairment = Impairment(config, np.random.default_rng(21))
    draws = _Draws(21)
    bound = 0.003 * 1e9
    for _ in range(3000):
        lost = draws.uniform() < 0.5
        if distribution == "uniform":
            jitter = draws.uniform() * bound
        elif distribution == "normal":
            jitter = bound * (0.5 + draws.generator.standard_normal() / 6.0)
        else:
            jitter = draws.generator.exponential(bound / 5.0)
        assert impairment.lost() is lost
        assert impairment.target_ns(T0) - T0 == int(min(max(jitter, 0.0), bound))


def test_no_loss_and_no_bursts_draw_nothing() -> None:
    """Loss 0 and burst entry 0 draw no uniform: the jitter takes the seed's uniforms in turn."""
    impairment = Impairment(InjectionConfig(jitter_s=0.5, preserve_order=False),
                            np.random.default_rng(22))
    got = []
    for _ in range(1500):
        assert impairment.lost() is False
        got.append(impairment.target_ns(T0) - T0)
    assert got == (_uniforms(22, 1500) * 0.5e9).astype(np.int64).tolist()


@pytest.mark.parametrize("distribution", ["uniform", "normal", "exponential"])
def test_no_jitter_draws_nothing(distribution) -> None:
    """Jitter 0 draws nothing: message k is lost iff the seed's k-th uniform is below p."""
    impairment = Impairment(InjectionConfig(loss_probability=0.5, delay_s=0.001,
                                            jitter_distribution=distribution),
                            np.random.default_rng(23))
    lost = []
    for k in range(1500):
        lost.append(impairment.lost())
        assert impairment.target_ns(T0 + k) == T0 + k + 1_000_000
    assert lost == (_uniforms(23, 1500) < 0.5).tolist()


# --- the loss decisions --------------------------------------------------------------------


def test_a_message_is_lost_only_when_its_uniform_is_below_the_probability() -> None:
    """Independent loss is u < p, strictly: p equal to the draw keeps the message."""
    u = _uniforms(31, 2)
    kept = Impairment(InjectionConfig(loss_probability=float(u[0])), np.random.default_rng(31))
    assert kept.lost() is False
    lost = Impairment(InjectionConfig(loss_probability=math.nextafter(u[0], 1.0)),
                      np.random.default_rng(31))
    assert lost.lost() is True
    assert all(Impairment(InjectionConfig(loss_probability=1.0),
                          np.random.default_rng(31)).lost() for _ in range(100))


def test_burst_transitions_and_burst_loss_are_strictly_below_their_probability() -> None:
    """Entering, leaving and burst loss each happen iff the uniform < the probability."""
    u = _uniforms(32, 4)  # message 1: enter u0, burst loss u1; message 2: exit u2, loss u3

    def run(**changes: float) -> list[tuple[bool, bool]]:
        config = InjectionConfig(**{"burst_enter_probability": 1.0, "burst_exit_probability":
                                    1e-300, "burst_loss_probability": 1.0, **changes})
        impairment = Impairment(config, np.random.default_rng(32))
        return [(impairment.lost(), impairment.in_burst) for _ in range(2)]

    assert run(burst_enter_probability=float(u[0]))[0] == (False, False)
    assert run(burst_enter_probability=math.nextafter(u[0], 1.0))[0] == (True, True)
    assert run(burst_loss_probability=float(u[1]))[0] == (False, True)
    assert run(burst_loss_probability=math.nextafter(u[1], 1.0))[0] == (True, True)
    assert run(burst_exit_probability=float(u[2]))[1] == (True, True)
    assert run(burst_exit_probability=math.nextafter(u[2], 1.0))[1] == (False, False)


def test_the_chain_starts_good_and_steps_before_the_loss_draw() -> None:
    """The chain starts in the good state and a message's loss uses the state it stepped to."""
    impairment = Impairment(InjectionConfig(burst_enter_probability=1.0), np.random.default_rng(0))
    assert impairment.in_burst is False
    # enter 1, exit 1, burst loss 1: good -> bad (lost), bad -> good (kept), ...
    pattern = [(impairment.lost(), impairment.in_burst) for _ in range(6)]
    assert pattern == [(True, True), (False, False)] * 3
    stuck = Impairment(InjectionConfig(burst_enter_probability=5e-324,
                                       burst_exit_probability=5e-324), np.random.default_rng(0))
    assert not any(stuck.lost() for _ in range(2000)) and stuck.in_burst is False


def _within_binomial(k: int, n: int, p: float) -> bool:
    """k inside the central 1 - 1e-6 interval of Binomial(n, p)."""
    low, high = binom.interval(1.0 - 1e-6, n, p)
    return low <= k <= high


def test_gilbert_elliott_probabilities_in_each_state() -> None:
    """Per state, transitions and losses follow their probabilities (binomial bounds, seeded)."""
    loss, enter, leave, burst_loss = 0.02, 0.05, 0.25, 0.6
    impairment = Impairment(InjectionConfig(loss_probability=loss,
                                            burst_enter_probability=enter,
                                            burst_exit_probability=leave,
                                            burst_loss_probability=burst_loss),
                            np.random.default_rng(41))
    n = 200_000
    before = np.empty(n, bool)
    after = np.empty(n, bool)
    lost = np.empty(n, bool)
    for k in range(n):
        before[k] = impairment.in_burst
        lost[k] = impairment.lost()
        after[k] = impairment.in_burst
    good, bad = ~before, before
    assert _within_binomial(int(np.sum(after[good])), int(good.sum()), enter)
    assert _within_binomial(int(np.sum(~after[bad])), int(bad.sum()), leave)
    # a message in the good state is lost by the independent loss only; in the bad state by
    # either: 1 - (1 - loss) (1 - burst_loss)
    assert _within_binomial(int(np.sum(lost[~after])), int((~after).sum()), loss)
    either = 1.0 - (1.0 - loss) * (1.0 - burst_loss)
    assert _within_binomial(int(np.sum(lost[after])), int(after.sum()), either)
    # the stationary share of the bad state, enter / (enter + leave) = 1/6 (loosely: the
    # states are correlated from one message to the next)
    assert abs(after.mean() - enter / (enter + leave)) < 0.01


def test_without_independent_loss_the_good_state_loses_nothing() -> None:
    """Bursts only: every loss happens in the bad state, at the burst loss probability."""
    impairment = Impairment(InjectionConfig(burst_enter_probability=0.1,
                                            burst_exit_probability=0.5,
                                            burst_loss_probability=0.3),
                            np.random.default_rng(42))
    n = 100_000
    states, lost = np.empty(n, bool), np.empty(n, bool)
    for k in range(n):
        lost[k] = impairment.lost()
        states[k] = impairment.in_burst
    assert not lost[~states].any()
    assert _within_binomial(int(lost[states].sum()), int(states.sum()), 0.3)
