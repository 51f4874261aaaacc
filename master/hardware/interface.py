"""The handle hardware interface (ros2_control style) and the registry of backends by name.

Lifecycle states and their meaning:

- ``unconfigured``: no communication;
- ``inactive`` (after :meth:`HandleHardware.configure`): the bus is up and the drives are
  set up; ``read()`` gives states, ``write()`` sends no motion command;
- ``active`` (after :meth:`HandleHardware.activate`): the drives are enabled and commands
  are accepted; on activation the command is set to the current position (no jump);
- ``deactivate()`` returns to ``inactive`` (drives disabled), ``cleanup()`` to
  ``unconfigured`` (bus closed).

``read()`` only updates state (one control cycle's sample), ``write()`` only sends the
commands. A backend is chosen by name (``[master] rig``, ``haptic-master --rig``) through
:func:`create_hardware`, never by a flag tested in control code.
"""

from __future__ import annotations

import importlib
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum
from typing import Any

import numpy as np

#: The handle's axes, in the order of every per-axis value (readings, commands, drives).
AXES = ("x", "y")


class LifecycleState(Enum):
    """ros2_control-style lifecycle states of a hardware component."""

    UNCONFIGURED = "unconfigured"
    INACTIVE = "inactive"
    ACTIVE = "active"


class HardwareError(RuntimeError):
    """A lifecycle transition failed (no reply, a drive would not enable, a bad SDO)."""


@dataclass(frozen=True)
class HandleReading:
    """One cycle's sample of the handle (x, y).

    ``force_N``: the operator's force on the sensor, N; ``position_m``: the handle position
    from the encoders, m. A value the cycle did not deliver is NaN. ``faults`` lists what
    went wrong this cycle (a missing PDO, a drive fault, an EMCY); empty when healthy.
    ``cycle`` counts SYNCs since configure. ``events`` lists what changed without being a
    fault (a drive's statusword warning bits, once per change).
    """

    force_N: np.ndarray
    position_m: np.ndarray
    cycle: int
    faults: tuple[str, ...] = ()
    events: tuple[str, ...] = ()

    @property
    def ok(self) -> bool:
        """True when the cycle reported no fault."""
        return not self.faults


class HandleHardware(ABC):
    """The handle: two position-servoed axes and a two-channel force sensor."""

    @property
    @abstractmethod
    def lifecycle_state(self) -> LifecycleState:
        """The current lifecycle state."""

    @abstractmethod
    def configure(self) -> None:
        """unconfigured -> inactive: open the bus, set the drives up; raise
        :class:`HardwareError` on failure."""

    @abstractmethod
    def activate(self) -> None:
        """inactive -> active: enable the drives holding the current position."""

    @abstractmethod
    def deactivate(self) -> None:
        """active -> inactive: disable the drives (the lead screws hold the handle)."""

    @abstractmethod
    def cleanup(self) -> None:
        """-> unconfigured: close the bus (safe to call in any state)."""

    def device_process_cpu_s(self) -> float | None:
        """CPU time the process the devices run in has used so far, s, where that is another
        process of this host (the ``sim`` backend's rig emulator, which shares the machine
        with the loops); None otherwise (real devices, devices in this process)."""
        return None

    def summary(self) -> dict[str, Any]:
        """What the hardware adds to the run's summary after configure (the CAN backends: the
        fallbacks taken for what a drive's EDS lacks, each drive's PDOs and watchdogs); the
        default adds nothing."""
        return {}

    def sync(self) -> None:
        """Start the next control cycle ahead of its :meth:`read` (the CAN backends send its
        SYNC: the devices sample and answer while the loop waits for its tick, the runner's
        ``lead``); :meth:`read` then collects that cycle. Optional: :meth:`read` starts the
        cycle itself when this was not called. The default does nothing (a backend that
        samples in :meth:`read`)."""
        return None

    @abstractmethod
    def read(self) -> HandleReading:
        """One control cycle's sample (a SYNC on the CAN backends)."""

    @abstractmethod
    def write(self, position_command_m: np.ndarray) -> None:
        """Send the axis position commands (x, y), m; ignored unless active."""

    def stop_motion(self, reason: str) -> None:
        """The master's own safety trip (``reason``: the watchdog, the node's safety layer, a
        tool input fault): forces are off and the program commands the hold position; a rig
        whose drives can stop themselves does so too (CiA 402 quick stop), and reports each
        drive's transition as an event (or a fault when it does not take it) in the next
        readings. The default does nothing more than the commanded hold. Never raises."""
        del reason

    def resume_motion(self) -> None:
        """Forces come back after :meth:`stop_motion`: the drives are re-enabled holding where
        they are (target = actual position) before the loop commands them again; a failure is
        a fault in the next reading (the drives stay stopped). The default does nothing.
        Never raises."""
        return None

    def present_tool_force(self, tool_force_N: np.ndarray) -> None:
        """The tool force (N, x and y) the master is reflecting this cycle. Real hardware
        ignores it (the operator feels it through the handle); a simulated rig hands it to
        its operator model. Not a command: it never moves anything."""
        del tool_force_N

    def present_forces_enabled(self, enabled: bool) -> None:
        """Whether the master's forces are enabled (the rig's ready lamp). Real hardware may
        show it to the operator; a simulated rig's operator grasps the handle, and the clock
        of its script starts, the first time it comes on (a real operator waits for the lamp
        too). Not a command: it never moves anything."""
        del enabled

    def __enter__(self) -> HandleHardware:
        return self

    def __exit__(self, *exc: object) -> None:
        self.cleanup()


def starts_cycles_early(hardware: HandleHardware) -> bool:
    """Whether ``hardware`` has a :meth:`HandleHardware.sync` of its own (the CAN backends:
    the loop then sends each SYNC ``[master.can] sync_lead_s`` before its tick)."""
    return type(hardware).sync is not HandleHardware.sync


HardwareFactory = Callable[[dict[str, Any]], HandleHardware]

#: The built-in backends as data, name -> ``"module:factory"`` (``factory(config) ->
#: HandleHardware``), the way python-can names its interfaces: this module imports no
#: backend, so the backends may import it without a cycle, and a backend's heavy imports
#: (the CAN stack) load only when that backend is chosen.
BACKENDS: dict[str, str] = {
    "can": "haptic.master.hardware.can_driver:can_hardware",
    "model": "haptic.master.simulated_rig.model_backend:model_rig_hardware",
    "sim": "haptic.master.simulated_rig.rig_emulator:emulated_rig_hardware",
    "sim-inproc": "haptic.master.simulated_rig.can_devices:simulated_rig_hardware",
}


def hardware_names() -> tuple[str, ...]:
    """Names of the built-in backends."""
    return tuple(sorted(BACKENDS))


def hardware_factory(name: str) -> HardwareFactory:
    """The factory of the backend called ``name``, imported on first use."""
    try:
        target = BACKENDS[name]
    except KeyError:
        raise KeyError(f"no handle hardware named {name!r}; known: "
                       f"{', '.join(hardware_names())}") from None
    module_name, _, attribute = target.partition(":")
    return getattr(importlib.import_module(module_name), attribute)


def create_hardware(name: str, config: dict[str, Any]) -> HandleHardware:
    """The backend called ``name``, built from a validated configuration."""
    return hardware_factory(name)(config)
