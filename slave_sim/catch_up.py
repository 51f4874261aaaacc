"""One tick's node steps of the program's lane in one Warp launch: node and clay together,
every master sample of the tick in order (slave_sim/catch_up_kernels.py).

A tick that takes k master samples (a catch-up after a late message, slave_sim/pacing.py)
costs k node steps; stepped apart, each is four launches and a pass of Python (the inputs
written, the clay's inputs copied, the outputs built), which is most of a step's time on the
CPU. :class:`CatchUpStep` writes the k samples once, launches one kernel that runs the same
arithmetic on the same buffers, and builds the last sample's outputs once: the node's state,
the clay and the outputs are those of :meth:`SlaveNode.step` called once per sample, bit for
bit (tests/slave_sim/test_catch_up.py).

It applies where that kernel runs the whole step: one lane, the Warp clay on the CPU, no
active TDPA layer (its numpy acts between the node's stages), the clay's contact started
(its first step places the proxy in Python); :meth:`CatchUpStep.applies` says so each tick,
and the tick steps the node apart otherwise.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from haptic.common.runtime.replayed_launch import ReplayedLaunch
from haptic.slave_sim.catch_up_kernels import SAMPLE_COLUMNS, catch_up_kernel
from haptic.slave_sim.clay.sim import WarpClay
from haptic.slave_sim.node import DEVICE, SlaveNode, SlaveOutputs, SlaveState

#: The most samples one launch takes (a longer tick launches again).
MAX_SAMPLES = 8
#: One sample: handle force (fx, fy) N, position (x, y) m, force ramp 0..1.
Sample5 = tuple[float, float, float, float, float]


class CatchUpStep:
    """The one launch over ``state`` (of ``node``, one lane, the Warp clay on the CPU);
    :meth:`of` builds it where it can apply."""

    def __init__(self, node: SlaveNode, state: SlaveState, clay: WarpClay) -> None:
        import warp as wp

        runtime = state.kernels
        kernel = catch_up_kernel(runtime.layout)
        wp.load_module(kernel.module, device=DEVICE)  # never inside a tick
        samples = wp.zeros((MAX_SAMPLES, len(SAMPLE_COLUMNS)), dtype=wp.float64, device=DEVICE)
        count = wp.zeros(1, dtype=wp.int32, device=DEVICE)
        removed = wp.zeros(MAX_SAMPLES, dtype=wp.float64, device=DEVICE)
        self._launch = ReplayedLaunch(wp.launch(
            kernel, dim=1, device=DEVICE, record_cmd=True,
            inputs=[samples, count, removed, *runtime.step_arguments,
                    *clay.step_arguments(state.environment)]))
        self._buffers = (samples, count, removed)  # own the memory of the views below
        self._samples = samples.numpy()
        self._count = count.numpy()
        self._removed = removed.numpy()
        self._runtime = runtime
        self._environment = state.environment
        self._clay_host = state.environment.runtime["host"]
        self._position_ratio = tuple(float(ratio) for ratio in node.position_ratio)

    @classmethod
    def of(cls, node: SlaveNode, state: SlaveState) -> CatchUpStep | None:
        """The launch for ``state`` where the fused kernel can run its steps (one lane, the
        Warp clay on the CPU), else None."""
        clay = getattr(node.environment, "clay", None)
        if (state.lanes != 1 or state.kernels is None or not isinstance(clay, WarpClay)
                or clay.device != "cpu"):
            return None
        return cls(node, state, clay)

    def applies(self, state: SlaveState) -> bool:
        """Whether :meth:`step` steps ``state`` as :meth:`SlaveNode.step` would: the state
        it was built over, the clay's contact started, no active TDPA layer."""
        port = state.passivity
        return (state.kernels is self._runtime and state.environment is self._environment
                and state.environment.contact_all_ready
                and (port is None or not port.active[0]))

    def step(self, state: SlaveState, samples: Sequence[Sample5], zero_force: bool,
             handle_position_m: np.ndarray) -> SlaveOutputs:
        """Step ``state`` once per entry of ``samples`` (at least one), in order, with its
        handle force (zero where ``zero_force``: a tool that does not run), position and
        force ramp; returns the last step's outputs. ``handle_position_m``: the (1, 2) array
        the state keeps as its ``handle_position_m`` afterwards (the caller's, which holds
        the tick's newest input, as :meth:`SlaveNode.step` keeps its argument)."""
        for start in range(0, len(samples), MAX_SAMPLES):
            self._launch_samples(state, samples[start:start + MAX_SAMPLES], zero_force)
        state.step_count += len(samples)
        state.handle_position_m = handle_position_m
        _, _, handle_x_m, handle_y_m, _ = samples[-1]
        return self._outputs(state, handle_x_m, handle_y_m)

    def _launch_samples(self, state: SlaveState, samples: Sequence[Sample5],
                        zero_force: bool) -> None:
        """One launch over ``samples`` (at most :data:`MAX_SAMPLES`), with the inputs the
        node writes before a step (ft, the gain ratio) and the clay's removal added up."""
        rows = self._samples
        for index, (fx, fy, yx, yy, scale) in enumerate(samples):
            row = rows[index]
            if zero_force:
                row[0] = row[1] = 0.0
            else:
                row[0] = fx
                row[1] = fy
            row[2] = yx
            row[3] = yy
            row[4] = scale
        runtime = self._runtime
        inputs = runtime.inputs_row
        ft, gain = state.tool_force_N, state.gain_ratio
        inputs[4] = ft[0, 0]
        inputs[5] = ft[0, 1]
        inputs[7] = 1.0 if gain is None else gain[0]
        runtime.unit_scale = runtime.unit_gain = False  # the node's columns written here
        count = len(samples)
        self._count[0] = count
        self._launch.launch()
        total, removed = state.environment.removed_total_m3, self._removed
        for index in range(count):  # in order, as each step adds its own
            total[0] += removed[index]
        state.tool_force_N = self._tool_force(state)

    def _tool_force(self, state: SlaveState) -> np.ndarray:
        """ft of the last step (1, 2), N: the clay's force, zero on a halted lane."""
        force = self._clay_host["force"].copy()
        if self._runtime.halted_count[0]:
            force[state.halted] = 0.0
        return force

    def _outputs(self, state: SlaveState, handle_x_m: float, handle_y_m: float
                 ) -> SlaveOutputs:
        """The last step's outputs, the values :meth:`SlaveNode.step` gives
        (``handle_x_m``, ``handle_y_m``: the last sample's position, m), in fewer numpy
        calls than it takes: the cutting flag is the result's 1.0/0.0 column as bools;
        the tracking error ``yt - Ah1 yh`` is computed on floats, the same IEEE products and
        differences numpy's elementwise ones are."""
        tool = state.tool
        tool_x_m, _, tool_y_m, _ = tool[0].tolist()
        ratio_x, ratio_y = self._position_ratio
        result = self._clay_host["result"]  # the yield kernel's columns
        state.actuator_force_N = actuator = self._runtime.actuator.copy()
        return SlaveOutputs(
            tool_position_m=tool[:, 0::2].copy(),
            tool_velocity_m_s=tool[:, 1::2].copy(),
            tool_force_N=state.tool_force_N,
            actuator_force_N=actuator,
            cutting=result[:, 1].astype(bool),
            engagement=result[:, 2].copy(),
            removed_volume_m3=result[:, 0].copy(),
            tracking_error_m=np.array([[tool_x_m - ratio_x * handle_x_m,
                                        tool_y_m - ratio_y * handle_y_m]]),
        )

