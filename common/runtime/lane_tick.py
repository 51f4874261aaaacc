"""What the master's and the slave's ticks (master/tick.py, slave_sim/tick.py) share: the flags
of a tick's messages as ``Flags``, and the setup of a tick of one lane (``configure_lane``):
its passivity layer's wire side, and what stands for the setup before it is made.
"""

from __future__ import annotations

from typing import Any, NoReturn

from haptic.common.wire.messages import FLAGS_BY_VALUE, Flags
from haptic.common.wire.passivity_link import PassivityLink


class TickFlags:
    """A tick output's flags of each lane's message to the peer: the subclass (a dataclass)
    holds them as ``flag_values`` ((lanes,) int; ints because ``IntFlag`` arithmetic costs
    about a microsecond per operation, too much per lane and tick)."""

    flag_values: Any

    @property
    def flags(self) -> list[Flags]:
        """Per lane, the flags of the message to the peer."""
        return [FLAGS_BY_VALUE[value] for value in self.flag_values.tolist()]


def one_lane_passivity(lanes: int, node: Any) -> PassivityLink:
    """The passivity layer's wire side of a tick of one lane (a program's, a real-link
    cell's): ``tdpa`` where ``node`` runs the layer, not on standby for the governor. Raises
    ``ValueError`` for a tick of ``lanes`` != 1 (the lockstep's lanes go through the tick's
    lane-wise stages)."""
    if lanes != 1:
        raise ValueError("step_lane runs one lane (the lockstep's lanes: supervise, control)")
    return PassivityLink(node.passivity is not None and not node.passivity_standby)


class LaneNotConfiguredError(RuntimeError, AttributeError):
    """A one-lane tick stepped before its ``configure_lane`` (an ``AttributeError`` too, so
    that ``hasattr`` and copying see a missing attribute)."""


class UnconfiguredLane:
    """Stands for a one-lane tick's setup before ``configure_lane``: reading any of its
    attributes raises :class:`LaneNotConfiguredError` (a null object, so that ``step_lane``'s
    hot path needs no check of its own)."""

    __slots__ = ()

    def __getattr__(self, name: str) -> NoReturn:
        if name.startswith("__"):
            raise AttributeError(name)
        raise LaneNotConfiguredError(f"configure_lane before the lane's tick (its {name} is "
                                     "not set)")


#: the setup of every one-lane tick before ``configure_lane``
UNCONFIGURED_LANE: Any = UnconfiguredLane()
