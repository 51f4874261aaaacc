"""Time-domain simulation of the linear loop of one axis with a round-trip delay line.

It executes, sample by sample, exactly the sampled-data loop that
:class:`haptic.common.analysis.loop.AxisLoop` analyses with ``sample_period_s``: zero-order
hold plants Ph (handle with the operator's arm) and Pt (tool with the environment), Tustin
compensators, the master's command applied one sample late, the slave's environment force
taken at the end of its step, and integer-sample delays on the two cross channels. Lanes are
independent runs (same compensators, each with its own delay), stepped together.

It is the reference against which the analysis is checked: a delay just below the analytic
margin must decay, one just above must grow.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from haptic.common.model.lti import Path, combine, discretize
from haptic.common.model.plants import handle_with_operator, tool_with_environment
from haptic.common.model.synthesis import AxisCompensators
from haptic.common.model.teleop import AxisModel


@dataclass(frozen=True)
class LoopTraces:
    """Sampled signals of a run, shape (steps, lanes); forces in N, commands in m and N."""

    time_s: np.ndarray
    handle_force_N: np.ndarray
    tool_force_N: np.ndarray
    handle_command_m: np.ndarray
    tool_actuator_force_N: np.ndarray


class LinearLoopSimulator:
    """The sampled linear loop of one axis at ``sample_period_s`` (see module docstring)."""

    def __init__(
        self, axis: AxisModel, compensators: AxisCompensators, sample_period_s: float
    ) -> None:
        ts = sample_period_s
        self.sample_period_s = ts
        self.handle_plant = discretize(handle_with_operator(axis), ts, "zoh", "vh_m", "arm_force_N")
        self.tool_plant = discretize(tool_with_environment(axis), ts, "zoh", "vt_N", "ft_N")
        self.master = combine(
            [Path(discretize(compensators.ch1, ts, "tustin"), 0, 0, 1.0),
             Path(discretize(compensators.ct1, ts, "tustin"), 1, 0, -1.0)],
            ("fh_N", "ft_recv_N"), ("vh_m",),
        )
        self.slave = combine(
            [Path(discretize(compensators.ch2, ts, "tustin"), 0, 0, -1.0),
             Path(discretize(compensators.ct2, ts, "tustin"), 1, 0, 1.0)],
            ("fh_recv_N", "ft_N"), ("vt_N",),
        )

    def run(
        self,
        operator_force_N: np.ndarray,
        round_trip_delay_samples: np.ndarray,
        environment_force_N: np.ndarray | None = None,
    ) -> LoopTraces:
        """Simulate ``operator_force_N`` (uh, shape (steps,) or (steps, lanes)) through the
        loop; lane i delays the handle force by ``d_i // 2`` samples and the tool force by
        the rest. ``environment_force_N`` is ut (same shapes), zero by default."""
        delays = np.atleast_1d(np.asarray(round_trip_delay_samples, int))
        if np.any(delays < 0):
            raise ValueError("delays must be >= 0 samples")
        lanes = delays.size
        steps = operator_force_N.shape[0]
        uh = np.broadcast_to(operator_force_N.reshape(steps, -1), (steps, lanes))
        ut = np.zeros((steps, lanes)) if environment_force_N is None else np.broadcast_to(
            environment_force_N.reshape(steps, -1), (steps, lanes))
        to_slave = delays // 2
        to_master = delays - to_slave
        history = int(delays.max()) + 1
        lane_index = np.arange(lanes)

        xh, xt = self.handle_plant.initial_state(lanes), self.tool_plant.initial_state(lanes)
        xm, xs = self.master.initial_state(lanes), self.slave.initial_state(lanes)
        hp, tp = self.handle_plant, self.tool_plant
        fh_line = np.zeros((history, lanes))
        ft_line = np.zeros((history, lanes))
        vh_applied = np.zeros((lanes, 1))
        vt_held = np.zeros((lanes, 1))
        out = {name: np.empty((steps, lanes)) for name in ("fh", "ft", "vh", "vt")}
        for k in range(steps):
            # Master: sensor at SYNC k sees the command applied since SYNC k.
            arm_force = xh @ hp.C.T + vh_applied @ hp.D.T
            fh = uh[k] - arm_force[:, 0]
            slot = k % history
            fh_line[slot] = fh
            # Slave: environment force at the end of its last step (held force vt).
            ft = (xt @ tp.C.T + vt_held @ tp.D.T)[:, 0] - ut[k]
            ft_line[slot] = ft
            ft_recv = ft_line[(k - to_master) % history, lane_index]
            fh_recv = fh_line[(k - to_slave) % history, lane_index]
            fh_recv = np.where(k >= to_slave, fh_recv, 0.0)
            ft_recv = np.where(k >= to_master, ft_recv, 0.0)
            vh = self.master.step(xm, np.stack([fh, ft_recv], axis=1))
            vt = self.slave.step(xs, np.stack([fh_recv, ft], axis=1))
            # Plants advance: the handle with the command applied now (written last cycle),
            # the tool with the force just computed.
            xh[...] = xh @ hp.A.T + vh_applied @ hp.B.T
            xt[...] = xt @ tp.A.T + vt @ tp.B.T
            vh_applied = vh
            vt_held = vt
            out["fh"][k], out["ft"][k] = fh, ft
            out["vh"][k], out["vt"][k] = vh[:, 0], vt[:, 0]
        return LoopTraces(
            time_s=np.arange(steps) * self.sample_period_s,
            handle_force_N=out["fh"], tool_force_N=out["ft"],
            handle_command_m=out["vh"], tool_actuator_force_N=out["vt"],
        )


def growth_ratio(signal: np.ndarray, window_samples: int) -> np.ndarray:
    """Peak |signal| in the last window over the peak in the window after the first one, per
    lane: below 1 the response decays, above 1 it grows."""
    first = np.max(np.abs(signal[window_samples:2 * window_samples]), axis=0)
    last = np.max(np.abs(signal[-window_samples:]), axis=0)
    return last / np.maximum(first, 1e-300)
