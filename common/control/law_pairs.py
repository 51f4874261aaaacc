"""The lane laws' two sides (wave variables, four-channel with and without its TDPA,
model-mediated) as one interface, :class:`ControlPair`, and the servo device a side's command
drives: what the comparison's lane simulator (lockstep/compare_lanes.py), its real-link cells
and both programs' law modes (master/law_stages.py, slave_sim/law_stages.py) step, so that a
law runs one implementation everywhere.

A pair's ``master`` takes the operator's force on the handle and the newest tool message and
writes its handle message; its ``slave`` takes the force the tool applies to its environment,
the tool's motion and the newest handle message and writes its tool message; each returns its
device's command: (position m or None, velocity m/s). With no position command the device
follows the integral of the velocity commands (:class:`Device`, :class:`CommandIntegrator`).
Arrays are (lanes, 2): x and y.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from haptic.common.control.four_channel import FourChannelGains, Impedance, side_laws
from haptic.common.control.four_channel_kernel import FourChannelSideKernel
from haptic.common.control.four_channel_passivity import MASTER_PORT_SIGN, SLAVE_PORT_SIGN
from haptic.common.control.four_channel_tdpa_kernel import PassiveFourChannelSideKernel
from haptic.common.control.law_settings import (
    LANE_CONTROLS,
    PERIOD_S,
    WAVE_IMPEDANCE_N_S_PER_M,
    LawSettings,
)
from haptic.common.control.mmt import EnvironmentModel, EstimatorSettings, RendererSettings
from haptic.common.control.mmt_kernel import EstimatorKernel, RendererKernel
from haptic.common.control.wave import (
    MASTER_SIGN,
    MESSAGE_CHANNELS,
    SLAVE_SIGN,
    message_fields,
)
from haptic.common.control.wave_kernel import WavePortKernel
from haptic.common.model.passivity import PassivityPort

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
#: The four-channel manipulators and local controllers (the tests' values), transparent
#: channels without the masses (docs/architectures.md, "A sampled loop and the masses").
FOUR_CHANNEL_MANIPULATOR = Impedance(mass_kg=0.1, damping_N_s_per_m=1.0)
FOUR_CHANNEL_LOCAL = Impedance(damping_N_s_per_m=50.0, stiffness_N_per_m=500.0)




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

    def __init__(self, lanes: int, settings: LawSettings | None = None) -> None:
        settings = (settings or LawSettings()).wave_settings()
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

    def __init__(self, lanes: int, settings: LawSettings | None = None) -> None:
        master_law, slave_law = side_laws(four_channel_gains(),
                                          (settings or LawSettings()).period_s)
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

    def __init__(self, lanes: int, law_settings: LawSettings | None = None) -> None:
        law_settings = law_settings or LawSettings()
        master_law, slave_law = side_laws(four_channel_gains(), law_settings.period_s)
        settings = law_settings.passivity
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

    def __init__(self, lanes: int, settings: LawSettings | None = None) -> None:
        period_s = (settings or LawSettings()).period_s
        start = np.zeros((lanes, 2))
        self.renderer = RendererKernel(RendererSettings(period_s=period_s), start)
        self.estimator = EstimatorKernel(EstimatorSettings(period_s=period_s), start)

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
    integral of its velocity commands (m) where the law commands no position; ``period_s``
    its step, s."""

    mass_kg: float
    damping_N_s_per_m: float
    position_m: np.ndarray
    velocity_m_per_s: np.ndarray
    integrated_command_m: np.ndarray
    period_s: float = PERIOD_S

    @classmethod
    def at_rest(cls, mass_kg: float, damping_N_s_per_m: float, lanes: int,
                start_m: np.ndarray | None = None, period_s: float = PERIOD_S) -> Device:
        """At rest at ``start_m`` ((2,) or (lanes, 2), m; default 0)."""
        start = np.zeros((lanes, 2)) if start_m is None else np.broadcast_to(
            np.asarray(start_m, float), (lanes, 2)).copy()
        return cls(mass_kg, damping_N_s_per_m, start, np.zeros((lanes, 2)), start.copy(),
                   period_s)

    def step(self, command_m: np.ndarray | None, command_m_per_s: np.ndarray,
             force_N: np.ndarray) -> None:
        """One period towards the command under the external force (implicit Euler in the
        servo's spring and damper and the device's damping); no position command: the
        integral of the velocity commands, within ``SERVO_FORCE_LIMIT_N`` of the servo's
        spring from the device's position."""
        w = SERVO_FREQUENCY_RAD_S
        stiffness, damping = self.mass_kg * w * w, 2.0 * self.mass_kg * w
        ts = self.period_s
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


def passivity_port(pair: ControlPair, side: str) -> PassivityPort | None:
    """The passivity layer's port of one ``side`` ("master" or "slave") of ``pair``, or None
    for a law without the layer (what
    :func:`~haptic.common.model.passivity.passivity_summary` reports)."""
    if side not in ("master", "slave"):
        raise ValueError(f"a side is master or slave (got {side!r})")
    if not isinstance(pair, PassiveFourChannelPair):
        return None
    return (pair.master_side if side == "master" else pair.slave_side).port


def make_pair(control: str, lanes: int, settings: LawSettings | None = None) -> ControlPair:
    """Both sides of ``control`` (one of :data:`LANE_CONTROLS`) over ``lanes`` lanes."""
    if control not in PAIRS:
        raise ValueError(f"a lane law is one of {', '.join(LANE_CONTROLS)} (got {control!r})")
    return PAIRS[control](lanes, settings)


__all__ = ["FOUR_CHANNEL_LOCAL", "FOUR_CHANNEL_MANIPULATOR", "HANDLE_DEVICE_DAMPING_N_S_PER_M",
           "HANDLE_DEVICE_MASS_KG", "LANE_CONTROLS", "PAIRS", "PERIOD_S",
           "SERVO_FORCE_LIMIT_N", "SERVO_FREQUENCY_RAD_S", "TOOL_DEVICE_DAMPING_N_S_PER_M",
           "TOOL_DEVICE_MASS_KG", "WAVE_IMPEDANCE_N_S_PER_M", "ControlPair", "Device",
           "FourChannelPair", "LawSettings", "ModelMediatedPair", "PassiveFourChannelPair",
           "WavePair", "four_channel_gains", "make_pair", "passivity_port"]
