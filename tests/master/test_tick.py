"""The master's tick over several lanes (as the lockstep runs it) is, lane by lane, the
program's one-lane tick: a lane whose watchdog trips and resumes gets its own fresh node
state, and the other lanes go on untouched."""

from __future__ import annotations

import numpy as np

from haptic.common.wire.messages import Flags, ToolState
from haptic.master.node import MasterNode
from haptic.master.settings import master_settings
from haptic.master.supervisor import MasterSupervisor, Transition
from haptic.master.tick import MasterTick

RESYNC = 5
MAX_AGE_S = 0.01
#: Lane 1 hears nothing from its slave over these ticks (longer than MAX_AGE_S).
OUTAGE = range(150, 200)


def _tick(node: MasterNode, lanes: int, ratio: tuple[float, float]) -> MasterTick:
    tick = MasterTick(node, [MasterSupervisor(ratio, 0.001, MAX_AGE_S, RESYNC)
                             for _ in range(lanes)])
    tick.start(np.zeros((lanes, 2)))
    return tick


def test_lanes_trip_and_resume_alone_and_equal_one_lane_ticks(paper_config,
                                                              paper_model) -> None:
    node = MasterNode.from_model(paper_model, master_settings(paper_config).safety)
    ts = paper_model.sample_period_s
    ratio = tuple(float(a.position_ratio_ah1) for a in paper_model.axes)
    both = _tick(node, 2, ratio)
    alone = [_tick(node, 1, ratio), _tick(node, 1, ratio)]
    last_heard = [0, 0]
    transitions: list[list[Transition]] = [[], []]
    position = np.zeros((2, 2))
    for k in range(400):
        now_s = k * ts
        # a small push then a larger one (the gate opens, the ramp runs), 0.3 N of tool force
        force = np.array([[0.05 if k < 60 else 1.5, 0.2], [0.05 if k < 60 else 1.0, -0.3]])
        messages: list[ToolState | None] = []
        for lane in range(2):
            if lane == 1 and k in OUTAGE:
                messages.append(None)
                continue
            last_heard[lane] = k
            tool_m = (ratio[0] * position[lane, 0], ratio[1] * position[lane, 1])
            messages.append(ToolState(1, k, 0, Flags.FORCES_ENABLED, (0.3, 0.0), tool_m,
                                      (0.0, 0.0), 0.0, 0.0))
        silence = [(k - heard) * ts for heard in last_heard]
        got = both.supervise(now_s, messages, position, silence_s=silence)
        out = both.control(force, position)
        for lane in range(2):
            ref = alone[lane]
            expected = ref.supervise(now_s, [messages[lane]], position[lane:lane + 1],
                                     silence_s=[silence[lane]])
            assert got[lane] is expected[0]
            transitions[lane].append(got[lane])
            ref_out = ref.control(force[lane:lane + 1], position[lane:lane + 1])
            np.testing.assert_array_equal(out.command_m[lane], ref_out.command_m[0])
            np.testing.assert_array_equal(out.handle_force_used_N[lane],
                                          ref_out.handle_force_used_N[0])
            np.testing.assert_array_equal(out.tool_force_used_N[lane],
                                          ref_out.tool_force_used_N[0])
            assert out.flags[lane] == ref_out.flags[0]
        position = out.command_m.copy()  # an ideal handle follows its command
    assert transitions[0].count(Transition.ACTIVATE) == 1
    assert Transition.HOLD not in transitions[0]  # lane 0 never noticed lane 1's outage
    assert transitions[1].count(Transition.HOLD) == 1
    assert transitions[1].count(Transition.RESUME) == 1
    assert both.state.forces_enabled.all()  # both lanes back with forces on
    assert abs(position[0, 0]) > 1e-4  # the push moved the handle
