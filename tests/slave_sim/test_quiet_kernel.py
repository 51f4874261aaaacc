"""The lockstep's quiet-lane kernel (slave_sim/quiet_kernel.py) against the program's own
checks: for every lane, the kernel takes a message as it is exactly when
:meth:`InputGuard.admit` would take it unchanged (no fault, saturation, rate limit or new
epoch) and the supervisor has nothing to change, and then leaves the guard's send clock
(common/wire/send_clock.py) as the guard leaves it; it leaves every other lane to them."""

from __future__ import annotations

import numpy as np

from haptic.common.wire.messages import Flags, HandleState
from haptic.common.wire.send_clock import SendClock, receive_time_ns
from haptic.slave_sim.input_guard import InputGuard, InputGuardSettings
from haptic.slave_sim.quiet_kernel import QuietLanes, guard_limits

PERIOD_S = 0.00054
SETTINGS = InputGuardSettings(force_limit_N=20.0, force_trip_N=60.0,
                              force_rate_limit_N_per_s=20000.0,
                              position_min_m=(-0.16, -0.16), position_max_m=(0.16, 0.16),
                              velocity_trip_m_per_s=1.0, jump_margin_m=0.001)
ENABLED = int(Flags.FORCES_ENABLED)
NOW_S = 12.345678901  # the tick's loop time, s
NOW_NS = receive_time_ns(NOW_S)


def _cases(rng: np.random.Generator, lanes: int) -> dict[str, np.ndarray]:
    """Last accepted values and new messages around every bound, with exact ties."""
    last_force = rng.uniform(-19.0, 19.0, (lanes, 2))
    last_position = rng.uniform(-0.15, 0.15, (lanes, 2))
    last_send = rng.integers(0, 10**9, lanes)  # the clock's credited send time, ns
    gap_ns = rng.choice([0, 1, 540_000, 1_080_000, 50_000_000], lanes)
    send = last_send + gap_ns
    last_received = NOW_NS - rng.choice([0, 540_000, 1_080_000, 10**9], lanes)
    # the sender's counted lead: mostly its usual one (the cap far), some just below the
    # message's (the cap bites), some above it (the lead does not rise)
    lead = send - NOW_NS - rng.choice([-10**6, 0, 1, 10**6, 40 * 10**6], lanes,
                                      p=[0.1, 0.3, 0.1, 0.1, 0.4])
    lead = np.where(rng.uniform(size=lanes) < 0.5, lead - SETTINGS.jitter_allowance_ns,
                    lead - 10**8)
    credited = np.minimum(send, NOW_NS + lead + SETTINGS.jitter_allowance_ns)
    dt_s = np.maximum((credited - last_send) * 1e-9, PERIOD_S)
    step = SETTINGS.force_rate_limit_N_per_s * dt_s
    allowed = SETTINGS.velocity_trip_m_per_s * dt_s + SETTINGS.jump_margin_m
    force = last_force + rng.uniform(-1.05, 1.05, (lanes, 2)) * np.minimum(step, 0.5)[:, None]
    position = last_position + rng.uniform(-1.05, 1.05, (lanes, 2)) * allowed[:, None]
    position[gap_ns == 50_000_000] = last_position[gap_ns == 50_000_000] + 0.02
    kind = rng.integers(0, 15, lanes)
    axis = rng.integers(0, 2, lanes)
    force[kind == 1, axis[kind == 1]] = np.nan
    position[kind == 2, axis[kind == 2]] = np.inf
    force[kind == 3, axis[kind == 3]] = SETTINGS.force_limit_N  # a tie: not saturated
    last_force[kind == 3, axis[kind == 3]] = SETTINGS.force_limit_N
    force[kind == 4, axis[kind == 4]] = 25.0  # saturated, below the trip
    force[kind == 5, axis[kind == 5]] = -80.0  # a trip
    position[kind == 6, axis[kind == 6]] = 0.2  # outside the box
    pick = kind == 7  # the rate limit's edge, exactly
    force[pick, axis[pick]] = last_force[pick, axis[pick]] + step[pick]
    pick = kind == 12  # just beyond the rate limit, well inside the force limit
    last_force[pick, axis[pick]] = 0.0
    force[pick, axis[pick]] = np.minimum(step[pick] * 1.01, 19.0)
    pick = kind == 13  # just beyond the rate limit downwards
    last_force[pick, axis[pick]] = 0.0
    force[pick, axis[pick]] = -np.minimum(step[pick] * 1.01, 19.0)
    pick = kind == 8  # the jump's edge, exactly
    position[pick, axis[pick]] = last_position[pick, axis[pick]] + allowed[pick]
    pick = kind == 14  # the edge of a jump over the stamps' time, which the cap may cut
    uncapped = SETTINGS.velocity_trip_m_per_s * np.maximum(gap_ns * 1e-9, PERIOD_S) \
        + SETTINGS.jump_margin_m
    position[pick, axis[pick]] = last_position[pick, axis[pick]] + uncapped[pick]
    epoch = np.where(kind == 9, 8, 7)
    position = np.clip(position, -0.2, 0.2, where=np.isfinite(position), out=position)
    faulted = kind == 10
    has_last = kind != 11
    return {"last_force": last_force, "last_position": last_position, "last_send": last_send,
            "last_received": last_received, "lead": lead, "force": force,
            "position": position, "send": send, "epoch": epoch, "faulted": faulted,
            "has_last": has_last}


def _clock(case: dict[str, np.ndarray], lane: int) -> SendClock:
    """The lane's guard's send clock before the message."""
    return SendClock(SETTINGS.jitter_allowance_ns, 7, int(case["last_send"][lane]),
                     int(case["last_received"][lane]), int(case["lead"][lane]))


def _taken_by_guard(case: dict[str, np.ndarray], lane: int) -> tuple[bool, SendClock]:
    """Whether the program's guard takes the lane's message as it is, and its send clock
    after the message."""
    guard = InputGuard(SETTINGS, PERIOD_S)
    if case["has_last"][lane]:
        guard.take_plain(1, tuple(case["last_force"][lane].tolist()),
                         tuple(case["last_position"][lane].tolist()), _clock(case, lane))
    guard.faulted = bool(case["faulted"][lane])
    events = len(guard.events)
    message = HandleState(int(case["epoch"][lane]), 1, int(case["send"][lane]),
                          Flags.FORCES_ENABLED, tuple(case["force"][lane].tolist()),
                          tuple(case["position"][lane].tolist()))
    admitted = guard.admit(message, NOW_S)
    return (admitted and not guard.faulted and len(guard.events) == events
            and guard.force_N == message.handle_force_N and case["has_last"][lane]
            and int(case["epoch"][lane]) == 7), guard.clock


def _quiet_lanes(lanes: int, case: dict[str, np.ndarray]) -> tuple[QuietLanes, dict]:
    views = {
        "guard_faulted": case["faulted"].copy(), "guard_has_last": case["has_last"].copy(),
        "steady": np.ones(lanes, bool), "max_age_s": np.full(lanes, 0.05),
        "tool": np.zeros((lanes, 4)), "work_area_m": np.tile([-0.1, 0.1, -0.1, 0.1],
                                                             (lanes, 1)),
        "handle_force_N": case["last_force"].copy(),
        "handle_position_m": case["last_position"].copy(),
        "guard_epoch": np.full(lanes, 7, np.int64),
        "guard_credited_ns": case["last_send"].astype(np.int64),
        "guard_received_ns": case["last_received"].astype(np.int64),
        "guard_lead_ns": case["lead"].astype(np.int64),
        "echo_send_time_ns": np.zeros(lanes, np.int64), "force_scale": np.ones(lanes),
        "unseen": np.zeros(lanes, np.int64), "admitted": np.zeros(lanes, bool)}
    return QuietLanes(lanes, guard_limits(SETTINGS, PERIOD_S), views), views


def test_a_message_is_taken_exactly_when_the_guard_takes_it_unchanged() -> None:
    lanes = 600
    case = _cases(np.random.default_rng(5), lanes)
    quiet, views = _quiet_lanes(lanes, case)
    fed = quiet.run(NOW_NS, np.ones(lanes, bool), case["force"], case["position"],
                    np.full(lanes, ENABLED, np.int64), case["epoch"].astype(np.int64),
                    case["send"].astype(np.int64), np.full(lanes, 0.5), np.zeros(lanes))
    expected, clocks = zip(*(_taken_by_guard(case, lane) for lane in range(lanes)),
                           strict=True)
    assert fed == [lane for lane in range(lanes) if not expected[lane]]
    taken = np.array(expected)
    assert 100 < taken.sum() < lanes - 100  # both kinds, many of each
    for lane in np.flatnonzero(taken).tolist():  # the clock moved on as the guard's did
        clock = clocks[lane]
        assert (int(views["guard_credited_ns"][lane]), int(views["guard_received_ns"][lane]),
                int(views["guard_lead_ns"][lane])) == (
                    clock.credited_ns, clock.received_ns, clock.lead_ns), lane
    for lane in np.flatnonzero(~taken).tolist():  # untouched
        assert (int(views["guard_credited_ns"][lane]), int(views["guard_lead_ns"][lane])) == (
            int(case["last_send"][lane]), int(case["lead"][lane]))
    capped = case["send"] > NOW_NS + case["lead"] + SETTINGS.jitter_allowance_ns
    risen = taken & (case["send"] - NOW_NS > case["lead"])
    assert (taken & capped).sum() > 10 and (~taken & capped).sum() > 10
    assert risen.sum() > 10
    np.testing.assert_array_equal(views["admitted"], taken)
    np.testing.assert_array_equal(views["handle_force_N"][taken], case["force"][taken])
    np.testing.assert_array_equal(views["handle_force_N"][~taken], case["last_force"][~taken])
    np.testing.assert_array_equal(views["handle_position_m"][taken], case["position"][taken])
    np.testing.assert_array_equal(views["echo_send_time_ns"][taken], case["send"][taken])
    np.testing.assert_array_equal(views["force_scale"], np.where(taken, 0.5, 1.0))
    np.testing.assert_array_equal(views["unseen"], taken.astype(np.int64))


def test_the_supervisor_conditions_make_a_lane_loud() -> None:
    """Not steady, silent, without FORCES_ENABLED or with STOPPING (the master's last
    message), the tool outside its work area: each sends the lane to its supervisor; a lane
    with no message and nothing to change stays quiet and takes nothing."""
    lanes = 10
    case = _cases(np.random.default_rng(1), lanes)
    case["force"][:] = case["last_force"]
    case["position"][:] = case["last_position"]
    case["epoch"][:] = 7
    case["faulted"][:] = False
    case["has_last"][:] = True
    quiet, views = _quiet_lanes(lanes, case)
    views["steady"][1] = False
    views["tool"][3, 2] = 0.2  # y beyond the work area
    silence = np.zeros(lanes)
    silence[2] = 0.06
    flags = np.full(lanes, ENABLED, np.int64)
    flags[4] = int(Flags.SAFE_STATE)
    flags[9] = ENABLED | int(Flags.STOPPING)
    fresh = np.ones(lanes, bool)
    fresh[5] = False
    views["tool"][6, 0] = 0.11  # x beyond the work area, then below it
    views["tool"][7, 0] = -0.11
    views["tool"][8, 2] = -0.11  # y below it
    fed = quiet.run(NOW_NS, fresh, case["force"], case["position"], flags,
                    case["epoch"].astype(np.int64), case["send"].astype(np.int64),
                    np.ones(lanes), silence)
    assert fed == [1, 2, 3, 4, 6, 7, 8, 9]
    assert views["admitted"].tolist() == [True] + [False] * 9
    assert views["unseen"].tolist() == [1] + [0] * 9
