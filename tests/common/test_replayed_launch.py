"""ReplayedLaunch: a recorded CPU launch replayed with its arguments packed once runs the
kernel exactly as ``Launch.launch()`` does, and anything it cannot replay stays a plain
launch."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from haptic.common.runtime.replayed_launch import ReplayedLaunch, host_array

wp.config.log_level = wp.LOG_WARNING


@wp.struct
class Gains:
    scale: wp.float64
    offset: wp.float64


@wp.kernel
def affine_accumulate(values: wp.array(dtype=wp.float64), total: wp.array(dtype=wp.float64),
                      steps: wp.array(dtype=wp.int32), gains: Gains, count: wp.int32):
    lane = wp.tid()
    values[lane] = gains.scale * values[lane] + gains.offset + wp.float64(lane)
    wp.atomic_add(total, 0, values[lane])
    if lane == 0:
        steps[0] = steps[0] + count


def _recorded(lanes: int) -> tuple[object, dict[str, np.ndarray]]:
    wp.init()
    values = wp.array(np.linspace(0.0, 1.0, lanes), dtype=wp.float64, device="cpu")
    total = wp.zeros(1, dtype=wp.float64, device="cpu")
    steps = wp.zeros(1, dtype=wp.int32, device="cpu")
    gains = Gains()
    gains.scale, gains.offset = 0.5, 0.25
    command = wp.launch(affine_accumulate, dim=lanes, device="cpu",
                        inputs=[values, total, steps, gains, 3], record_cmd=True)
    return command, {"values": values.numpy(), "total": total.numpy(), "steps": steps.numpy(),
                     "_keep": (values, total, steps)}


def test_a_replay_runs_what_the_recorded_launch_runs() -> None:
    plain, plain_views = _recorded(7)
    replayed_command, replayed_views = _recorded(7)
    replayed = ReplayedLaunch(replayed_command)
    assert not replayed.replaying
    for _ in range(25):
        plain.launch()
        replayed.launch()
    assert replayed.replaying  # the CPU device: from the second call on, straight to the kernel
    for name in ("values", "total", "steps"):
        np.testing.assert_array_equal(replayed_views[name], plain_views[name])
    assert replayed_views["steps"][0] == 75  # every call ran the kernel (the int argument too)


class _Unreplayable:
    """A launch command without Warp's CPU internals (another version, another device)."""

    device = None

    def __init__(self) -> None:
        self.calls = 0

    def launch(self) -> None:
        self.calls += 1


def test_what_cannot_be_replayed_stays_a_plain_launch() -> None:
    command = _Unreplayable()
    replayed = ReplayedLaunch(command)
    for _ in range(5):
        replayed.launch()
    assert command.calls == 5 and not replayed.replaying


def test_a_host_array_shares_the_numpy_memory_and_refuses_a_strided_view() -> None:
    values = np.zeros((3, 2))
    shared = host_array(values, wp.float64)
    values[1, 1] = 5.0
    assert shared.numpy()[1, 1] == 5.0 and shared.ptr == values.ctypes.data
    with pytest.raises(ValueError, match="contiguous"):
        host_array(np.zeros((3, 4))[:, 0:2], wp.float64)
