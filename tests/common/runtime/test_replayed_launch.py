"""ReplayedLaunch: a recorded CPU launch replayed with its arguments packed once runs the
kernel exactly as ``Launch.launch()`` does, and anything it cannot replay stays a plain
launch."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from haptic.common.runtime.replayed_launch import (
    InPlaceInputs,
    ReplayedLaunch,
    host_array,
    host_view,
)

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


@wp.kernel
def weighted_sum(values: wp.array2d(dtype=wp.float64), weight: wp.array(dtype=wp.int64),
                 out: wp.array(dtype=wp.float64)):
    lane = wp.tid()
    out[lane] = out[lane] + values[lane, 0] + wp.float64(weight[lane]) * values[lane, 1]


def _weighted_inputs(lanes: int) -> tuple[InPlaceInputs, np.ndarray]:
    """An InPlaceInputs of ``weighted_sum`` over its own buffers, and the output it adds to."""
    out = np.zeros(lanes)
    out_array = host_array(out, wp.float64)

    def record(inputs: list) -> ReplayedLaunch:
        return ReplayedLaunch(wp.launch(weighted_sum, dim=lanes, device="cpu",
                                        inputs=[*inputs, out_array], record_cmd=True))

    return InPlaceInputs((np.zeros((lanes, 2)), np.zeros(lanes, np.int64)),
                         (wp.float64, wp.int64), ("same_kind", "unsafe"), record), out


def test_inputs_are_read_in_place_while_the_same_arrays_come_and_copied_otherwise() -> None:
    """Arrays updated in place (a strided view among them) are read in place from their
    second call on; other arrays, another dtype and temporaries are copied; the sums are
    what numpy gives, whichever way each call went."""
    lanes = 6
    rng = np.random.default_rng(4)
    inputs, out = _weighted_inputs(lanes)
    expected = np.zeros(lanes)
    block = np.zeros((lanes, 5))
    values, weight = block[:, 1:3], np.zeros(lanes, np.int64)  # a strided view
    ways = []
    for tick in range(40):
        if tick == 15:  # other arrays: copied once, then read in place
            block = np.zeros((lanes, 5))
            values, weight = block[:, 2:4], np.zeros(lanes, np.int64)
        block[...] = rng.standard_normal(block.shape)
        weight[...] = rng.integers(-3, 4, lanes)
        if tick >= 30:  # another dtype (int32 weights), new objects each call: copied
            sources = (values, weight.astype(np.int32))
        else:
            sources = (values, weight)
        inputs.launch(sources)
        expected += values[:, 0] + weight * values[:, 1]
        np.testing.assert_allclose(out, expected, rtol=0, atol=1e-12)
        ways.append(inputs.in_place)
    assert ways[:2] == [False, False] and all(ways[2:15])
    assert ways[15:17] == [False, False] and all(ways[17:30])
    assert not any(ways[30:])


def test_arrays_that_cannot_be_read_in_place_are_refused_once_and_copied() -> None:
    inputs, out = _weighted_inputs(4)
    values = np.ones((4, 2))[::-1]  # a negative stride
    weight = np.full(4, 2, np.int32)  # another dtype than the buffer's
    for sources in ((values, np.full(4, 2, np.int64)), (np.ones((4, 2)), weight)):
        out[...] = 0.0
        for _ in range(5):
            inputs.launch(sources)
            assert not inputs.in_place
        np.testing.assert_array_equal(out, np.full(4, 15.0))


def test_a_host_view_reads_a_strided_view_in_place_and_refuses_a_reversed_one() -> None:
    block = np.zeros((3, 4))
    view = host_view(block[:, 1:3], wp.float64)
    block[2, 2] = 7.0
    assert view.numpy()[2, 1] == 7.0 and view.ptr == block[:, 1:3].ctypes.data
    with pytest.raises(ValueError, match="strides"):
        host_view(block[::-1], wp.float64)
