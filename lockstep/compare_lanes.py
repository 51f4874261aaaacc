"""The comparison's lane simulator for the laws of common/control: wave variables,
four-channel (plain, and with the TDPA on its ports) and model-mediated teleoperation, every
cell of a control one lane.

One tick (period ``Ts``), every lane at once:

1. the operator's hand and the environment give the measured forces from the devices' state:
   ``fh`` on the handle (free-sine: a spring and damper towards the sine; wall: the intent
   force through the paper's operator impedance; clay-cut: the clay sweep's steady push
   through the same impedance), ``fe`` the tool applies to the wall (``max(0, k p + b v)``
   inside, common/control/tasks.py's law with each lane's stiffness) or to the clay (the
   constant-rate scenario's Warp clay, which the paper's and TDPA's clay cells also cut);
2. the master reads the tool line and steps its law (a Warp kernel over the lanes), then
   sends on the handle line;
3. the slave reads the handle line and steps its law, then sends on the tool line;
4. each device, a mass and damper under a servo (implicit Euler in the servo and the damping:
   stable at any gain), follows its law's command under the external force (``+fh`` on the
   handle, ``-fe`` on the tool): a position and velocity servo, its position command the
   law's (four-channel, the model-mediated master) or the integral of the law's velocity
   command (wave variables, the model-mediated slave), kept within the servo's force limit
   of the device's position (anti-windup: blocked by a wall, an integral would grow and push
   with the servo's whole stiffness).

The hand's mass rides on the handle (the master device's mass includes it; the force sensor
does not see it). Positions start at 0; the tool's coordinates are the handle's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from haptic.common.config.scenario import load_scenario
from haptic.common.control.four_channel import FourChannelGains, Impedance, side_laws
from haptic.common.control.four_channel_kernel import FourChannelSideKernel
from haptic.common.control.four_channel_passivity import MASTER_PORT_SIGN, SLAVE_PORT_SIGN
from haptic.common.control.mmt import EnvironmentModel, EstimatorSettings, RendererSettings
from haptic.common.control.mmt_kernel import EstimatorKernel, RendererKernel
from haptic.common.control.tasks import free_motion_sine
from haptic.common.control.wave import (
    MASTER_SIGN,
    MESSAGE_CHANNELS,
    SLAVE_SIGN,
    WaveSettings,
    message_fields,
)
from haptic.common.control.wave_kernel import WavePortKernel
from haptic.common.model.passivity import PassivitySettings
from haptic.lockstep.compare_four_channel_tdpa import PassiveFourChannelSideKernel
from haptic.lockstep.compare_grid import CompareGrid, Lane
from haptic.lockstep.compare_links import lane_lines
from haptic.lockstep.compare_records import LaneRecords
from haptic.slave_sim.environment import ClayEnvironment

#: The laws' period, s: the paper's (common/config/defaults, section 4.1).
PERIOD_S = 0.00054
#: The handle device without the hand (kg, N s/m); the hand's 0.25 kg rides on it.
HANDLE_DEVICE_MASS_KG = 0.1
HANDLE_DEVICE_DAMPING_N_S_PER_M = 1.0
#: The tool device: the paper's virtual tool's mass (kg), a light damping (N s/m).
TOOL_DEVICE_MASS_KG = 1.0
TOOL_DEVICE_DAMPING_N_S_PER_M = 1.0
#: Both devices' servos: critically damped at this natural frequency, rad/s.
SERVO_FREQUENCY_RAD_S = 200.0
#: The largest force an integrated velocity command may ask of a servo's spring, N.
SERVO_FORCE_LIMIT_N = 40.0
#: Wave impedance b of the wave control, N s/m.
WAVE_IMPEDANCE_N_S_PER_M = 20.0
#: The four-channel manipulators and local controllers (the tests' values), transparent
#: channels without the masses (docs/architectures.md, "A sampled loop and the masses").
FOUR_CHANNEL_MANIPULATOR = Impedance(mass_kg=0.1, damping_N_s_per_m=1.0)
FOUR_CHANNEL_LOCAL = Impedance(damping_N_s_per_m=50.0, stiffness_N_per_m=500.0)
LANE_CONTROLS = ("wave", "four-channel", "four-channel-tdpa", "mmt")


def four_channel_gains() -> FourChannelGains:
    """The four-channel gains the comparison runs (and Llewellyn's test analyses)."""
    return FourChannelGains.transparent(FOUR_CHANNEL_MANIPULATOR, FOUR_CHANNEL_MANIPULATOR,
                                        FOUR_CHANNEL_LOCAL, FOUR_CHANNEL_LOCAL,
                                        channel_masses=False)


class ControlPair(Protocol):
    """Both sides of a control over the lanes: the messages' layouts and one period each."""

    handle_channels: int
    tool_channels: int

    def initial_messages(self, lanes: int) -> tuple[np.ndarray, np.ndarray]: ...

    def master(self, fh: np.ndarray, tool_message: np.ndarray, fresh: np.ndarray,
               handle_message: np.ndarray) -> tuple[np.ndarray | None, np.ndarray]:
        """One period of the master: (position command m or None, velocity command m/s);
        writes the message it sends into ``handle_message``."""

    def slave(self, fe: np.ndarray, position: np.ndarray, velocity: np.ndarray,
              handle_message: np.ndarray, fresh: np.ndarray, tool_message: np.ndarray
              ) -> tuple[np.ndarray | None, np.ndarray]:
        """One period of the slave, as :meth:`master`, writing into ``tool_message``."""


class WavePair:
    """Wave variables: each message is (wave, its integral, its energy) (common/control/wave.py's
    :data:`~haptic.common.control.wave.MESSAGE_CHANNELS`); each side commands a velocity."""

    handle_channels = tool_channels = MESSAGE_CHANNELS

    def __init__(self, lanes: int) -> None:
        settings = WaveSettings(period_s=PERIOD_S, impedance_N_s_per_m=WAVE_IMPEDANCE_N_S_PER_M)
        self.master_port = WavePortKernel(settings, lanes, MASTER_SIGN)
        self.slave_port = WavePortKernel(settings, lanes, SLAVE_SIGN)

    def initial_messages(self, lanes: int) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros((lanes, MESSAGE_CHANNELS)), np.zeros((lanes, MESSAGE_CHANNELS))

    def master(self, fh: np.ndarray, tool_message: np.ndarray, fresh: np.ndarray,
               handle_message: np.ndarray) -> tuple[np.ndarray | None, np.ndarray]:
        velocity, *sent = self.master_port.step(fh, *message_fields(tool_message), fresh)
        for field, value in zip(message_fields(handle_message), sent, strict=True):
            field[...] = value
        return None, velocity

    def slave(self, fe: np.ndarray, position: np.ndarray, velocity: np.ndarray,
              handle_message: np.ndarray, fresh: np.ndarray, tool_message: np.ndarray
              ) -> tuple[np.ndarray | None, np.ndarray]:
        command, *sent = self.slave_port.step(fe, *message_fields(handle_message), fresh)
        for field, value in zip(message_fields(tool_message), sent, strict=True):
            field[...] = value
        return None, command


class FourChannelPair:
    """Four-channel: each message is the side's (position, velocity, measured force)."""

    handle_channels = tool_channels = 6

    def __init__(self, lanes: int) -> None:
        master_law, slave_law = side_laws(four_channel_gains(), PERIOD_S)
        start = np.zeros((lanes, 2))
        self.master_side = FourChannelSideKernel(master_law, start)
        self.slave_side = FourChannelSideKernel(slave_law, start)

    def initial_messages(self, lanes: int) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros((lanes, 6)), np.zeros((lanes, 6))

    def master(self, fh: np.ndarray, tool_message: np.ndarray, fresh: np.ndarray,
               handle_message: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        position, velocity = self.master_side.step(fh, tool_message[:, :2], tool_message[:, 2:4],
                                                   tool_message[:, 4:], fresh)
        handle_message[:, :2] = position
        handle_message[:, 2:4] = velocity
        handle_message[:, 4:] = fh
        return position, velocity

    def slave(self, fe: np.ndarray, position: np.ndarray, velocity: np.ndarray,
              handle_message: np.ndarray, fresh: np.ndarray, tool_message: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
        command, rate = self.slave_side.step(fe, handle_message[:, :2], handle_message[:, 2:4],
                                             handle_message[:, 4:], fresh)
        tool_message[:, :2] = command
        tool_message[:, 2:4] = rate
        tool_message[:, 4:] = fe
        return command, rate


class PassiveFourChannelPair:
    """Four-channel with the TDPA on both ports (``four-channel-tdpa``): each message is the
    side's (position, velocity, measured force) and, in its last channel, the cumulative
    energy (J) the side's passivity observer handed over, as the ``tdpa`` mode's ``energy_J``.
    Both ports are on the laws' position commands, as the paper's master port
    (common/control/four_channel_passivity.py); the TDPA has its default settings
    (common/model/passivity.py)."""

    handle_channels = tool_channels = 7

    def __init__(self, lanes: int) -> None:
        master_law, slave_law = side_laws(four_channel_gains(), PERIOD_S)
        settings = PassivitySettings()
        start = np.zeros((lanes, 2))
        self.master_side = PassiveFourChannelSideKernel(master_law, settings,
                                                        settings.master_keep_J,
                                                        MASTER_PORT_SIGN, start)
        self.slave_side = PassiveFourChannelSideKernel(slave_law, settings,
                                                       settings.slave_keep_J,
                                                       SLAVE_PORT_SIGN, start)

    def initial_messages(self, lanes: int) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros((lanes, 7)), np.zeros((lanes, 7))

    def master(self, fh: np.ndarray, tool_message: np.ndarray, fresh: np.ndarray,
               handle_message: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        position, velocity = self.master_side.step(fh, tool_message[:, :2], tool_message[:, 2:4],
                                                   tool_message[:, 4:6], tool_message[:, 6],
                                                   fresh)
        handle_message[:, :2] = position
        handle_message[:, 2:4] = velocity
        handle_message[:, 4:6] = fh
        handle_message[:, 6] = self.master_side.port.sent_J
        return position, velocity

    def slave(self, fe: np.ndarray, position: np.ndarray, velocity: np.ndarray,
              handle_message: np.ndarray, fresh: np.ndarray, tool_message: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
        command, rate = self.slave_side.step(fe, handle_message[:, :2], handle_message[:, 2:4],
                                             handle_message[:, 4:6], handle_message[:, 6],
                                             fresh)
        tool_message[:, :2] = command
        tool_message[:, 2:4] = rate
        tool_message[:, 4:6] = fe
        tool_message[:, 6] = self.slave_side.port.sent_J
        return command, rate


class ModelMediatedPair:
    """Model-mediated: the handle line carries the handle's (position, velocity), the tool
    line the environment model's four fields; the master renders the model, the tool tracks
    the handle with a velocity command."""

    handle_channels = 4
    tool_channels = 8

    def __init__(self, lanes: int) -> None:
        start = np.zeros((lanes, 2))
        self.renderer = RendererKernel(RendererSettings(period_s=PERIOD_S), start)
        self.estimator = EstimatorKernel(EstimatorSettings(period_s=PERIOD_S), start)

    def initial_messages(self, lanes: int) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros((lanes, 4)), np.zeros((lanes, 8))

    def master(self, fh: np.ndarray, tool_message: np.ndarray, fresh: np.ndarray,
               handle_message: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        model = EnvironmentModel(*(tool_message[:, 2 * i:2 * i + 2] for i in range(4)))
        position, velocity, _ = self.renderer.step(fh, model, fresh)
        handle_message[:, :2] = position
        handle_message[:, 2:] = velocity
        return position, velocity

    def slave(self, fe: np.ndarray, position: np.ndarray, velocity: np.ndarray,
              handle_message: np.ndarray, fresh: np.ndarray, tool_message: np.ndarray
              ) -> tuple[np.ndarray | None, np.ndarray]:
        command, model = self.estimator.step(position, velocity, fe, handle_message[:, :2],
                                             handle_message[:, 2:], fresh)
        for i, field in enumerate(model):
            tool_message[:, 2 * i:2 * i + 2] = field
        return None, command


PAIRS = {"wave": WavePair, "four-channel": FourChannelPair,
         "four-channel-tdpa": PassiveFourChannelPair, "mmt": ModelMediatedPair}


@dataclass(eq=False)
class Device:
    """A mass and damper under a critically damped servo, over lanes (lanes, 2), with the
    integral of its velocity commands (m) where the law commands no position."""

    mass_kg: float
    damping_N_s_per_m: float
    position_m: np.ndarray
    velocity_m_per_s: np.ndarray
    integrated_command_m: np.ndarray

    @classmethod
    def at_rest(cls, mass_kg: float, damping_N_s_per_m: float, lanes: int) -> Device:
        """At rest at 0."""
        return cls(mass_kg, damping_N_s_per_m, *(np.zeros((lanes, 2)) for _ in range(3)))

    def step(self, command_m: np.ndarray | None, command_m_per_s: np.ndarray,
             force_N: np.ndarray) -> None:
        """One period towards the command under the external force (implicit Euler in the
        servo's spring and damper and the device's damping); no position command: the
        integral of the velocity commands, within ``SERVO_FORCE_LIMIT_N`` of the servo's
        spring from the device's position."""
        w = SERVO_FREQUENCY_RAD_S
        stiffness, damping = self.mass_kg * w * w, 2.0 * self.mass_kg * w
        ts = PERIOD_S
        if command_m is None:
            window = SERVO_FORCE_LIMIT_N / stiffness
            self.integrated_command_m[...] = np.clip(
                self.integrated_command_m + ts * command_m_per_s, self.position_m - window,
                self.position_m + window)
            command_m = self.integrated_command_m
        drive = force_N + stiffness * (command_m - self.position_m) + damping * command_m_per_s
        velocity = (self.mass_kg * self.velocity_m_per_s + ts * drive) / (
            self.mass_kg + ts * (damping + self.damping_N_s_per_m) + ts * ts * stiffness)
        self.velocity_m_per_s[...] = velocity
        self.position_m[...] = self.position_m + ts * velocity


@dataclass(frozen=True)
class LaneTasks:
    """The task of each lane as arrays: which lanes push into a wall and its stiffness, which
    cut the clay."""

    wall: np.ndarray  # (lanes,) bool
    stiffness_N_per_m: np.ndarray  # (lanes,)
    clay: np.ndarray  # (lanes,) bool

    @classmethod
    def of(cls, lanes: list[Lane]) -> LaneTasks:
        return cls(np.array([lane.task == "wall" for lane in lanes]),
                   np.array([lane.wall_stiffness_N_per_m for lane in lanes]),
                   np.array([lane.task == "clay-cut" for lane in lanes]))


class LaneClay:
    """The constant-rate scenario's Warp clay (a 10 cm block at 100 N s/m from x = 2 cm, the
    tool starting at 0, as in the lockstep's clay cells) on the clay-cut lanes only: each
    lane its own workpiece, cut along the tool's move of each period."""

    def __init__(self, tasks: LaneTasks) -> None:
        self.lanes = np.flatnonzero(tasks.clay)
        self.clay = None
        if self.lanes.size:
            self.clay = ClayEnvironment(load_scenario("constant-rate"), PERIOD_S, "warp", "cpu")
            self.state = self.clay.initial_state(self.lanes.size)
            self.previous_m = np.zeros((self.lanes.size, 2))

    def force_N(self, position_m: np.ndarray, velocity_m_per_s: np.ndarray) -> np.ndarray:
        """The force the tool applies to the clay (lanes, 2), N, 0 on the other lanes; the
        tool moved to ``position_m`` since the last call."""
        force = np.zeros_like(position_m)
        if self.clay is None:
            return force
        position, velocity = position_m[self.lanes], velocity_m_per_s[self.lanes]
        # a diverged lane's tool stays where it was for the clay and gets no force (as the
        # wall gives none to a non-finite position); its records show the divergence
        finite = (np.isfinite(position).all(axis=1) & np.isfinite(velocity).all(axis=1))[:, None]
        position = np.where(finite, position, self.previous_m)
        cut = self.clay.step(self.state, self.previous_m, position,
                             np.where(finite, velocity, 0.0), np.zeros_like(position))
        self.previous_m = position
        force[self.lanes] = np.where(finite & np.isfinite(cut.force_N), cut.force_N, 0.0)
        return force


def hand_force_N(grid: CompareGrid, tasks: LaneTasks, time_s: float, duration_s: float,
                 position_m: np.ndarray, velocity_m_per_s: np.ndarray) -> np.ndarray:
    """The operator's force on the handle (lanes, 2), N (see the module's docstring)."""
    task = grid.task
    target, target_rate = free_motion_sine(np.array([time_s]), task.sine_amplitude_m,
                                           task.sine_frequency_hz)
    track = (task.track_stiffness_N_per_m * (target - position_m)
             + task.track_damping_N_s_per_m * (target_rate - velocity_m_per_s))
    intent = np.zeros((2, 2))
    intent[0, 0] = task.push_force_N * min(1.0, time_s / (0.5 * duration_s))
    intent[1, 0] = task.cut_push_force_N * min(1.0, time_s / task.cut_rise_s)
    push = (np.where(tasks.clay[:, None], intent[1], intent[0])
            - task.hand_damping_N_s_per_m * velocity_m_per_s
            - task.hand_stiffness_N_per_m * position_m)
    return np.where((tasks.wall | tasks.clay)[:, None], push, track)


def wall_force_N(grid: CompareGrid, tasks: LaneTasks, position_m: np.ndarray,
                 velocity_m_per_s: np.ndarray) -> np.ndarray:
    """The force the tool applies to the wall (lanes, 2), N: ``max(0, k p + b v)`` along +x
    inside it, 0 outside and on the free-motion lanes."""
    depth = position_m[:, 0] - grid.task.wall_surface_m
    push = np.where(depth > 0.0, np.maximum(
        tasks.stiffness_N_per_m * depth + grid.task.wall_damping_N_s_per_m
        * velocity_m_per_s[:, 0], 0.0), 0.0)
    force = np.zeros_like(position_m)
    force[:, 0] = np.where(tasks.wall, push, 0.0)
    return force


def simulate_lanes(control: str, lanes: list[Lane], grid: CompareGrid) -> LaneRecords:
    """Run ``control`` (one of :data:`LANE_CONTROLS`) on every lane for the grid's
    duration; the records of the task axis."""
    if control not in PAIRS:
        raise ValueError(f"the lane simulator runs {', '.join(LANE_CONTROLS)} (got {control!r})")
    count = len(lanes)
    duration = grid.duration_s
    steps = int(round(duration / PERIOD_S))
    pair: ControlPair = PAIRS[control](count)
    handle_initial, tool_initial = pair.initial_messages(count)
    handle_line, tool_line = lane_lines(lanes, steps, PERIOD_S, grid.seed, handle_initial,
                                        tool_initial)
    tasks = LaneTasks.of(lanes)
    clay = LaneClay(tasks)
    handle = Device.at_rest(HANDLE_DEVICE_MASS_KG + grid.task.hand_mass_kg,
                            HANDLE_DEVICE_DAMPING_N_S_PER_M, count)
    tool = Device.at_rest(TOOL_DEVICE_MASS_KG, TOOL_DEVICE_DAMPING_N_S_PER_M, count)
    records = LaneRecords.create(PERIOD_S, steps, count)
    with np.errstate(over="ignore", invalid="ignore"):
        for k in range(steps):
            fh = hand_force_N(grid, tasks, k * PERIOD_S, duration, handle.position_m,
                              handle.velocity_m_per_s)
            fe = (wall_force_N(grid, tasks, tool.position_m, tool.velocity_m_per_s)
                  + clay.force_N(tool.position_m, tool.velocity_m_per_s))
            records.add(k, handle.position_m[:, 0], tool.position_m[:, 0], fh[:, 0], fe[:, 0])
            tool_message = tool_line.receive(k)
            master_command = pair.master(fh, tool_message, tool_line.fresh, handle_line.slot(k))
            handle_message = handle_line.receive(k)
            slave_command = pair.slave(fe, tool.position_m, tool.velocity_m_per_s,
                                       handle_message, handle_line.fresh, tool_line.slot(k))
            handle.step(*master_command, fh)
            tool.step(*slave_command, -fe)
    return records


def lane_steps(grid: CompareGrid) -> int:
    """Ticks of a run of ``grid``."""
    return int(math.floor(grid.duration_s / PERIOD_S + 0.5))


__all__ = ["LANE_CONTROLS", "PERIOD_S", "four_channel_gains", "lane_steps", "simulate_lanes"]
