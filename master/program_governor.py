"""The margin governor as ``haptic-master`` runs it: built and checked at start, fed the
link's echo once per tick.

:func:`start_governor` builds the tau*(k) table, prints it, and refuses a run whose delay
profile reaches beyond the margin of every gain (exit 3, unless ``--allow-unstable``);
:func:`governor_step` feeds the governor the echo of the newest tool message (the master's
whole tick calls it, master/tick.py ``MasterTick.step_lane``).
"""

from __future__ import annotations

import argparse
import sys
from typing import Any, TextIO

from haptic.common.analysis.preflight import (
    DEFAULT_ASSUMED_LINK_DELAY_S,
    EXIT_UNSTABLE,
    governor_enabled,
    round_trip_delay_s,
)
from haptic.common.model.teleop import TeleopModel
from haptic.master.margin_governor import GovernorDecision, MarginGovernor, governor_for


def tdpa_standby(config: dict[str, Any], args: argparse.Namespace) -> bool:
    """Whether the master builds the passivity layer switched off for the governor to switch
    on at run time: the governor is enabled with ``action = "tdpa"`` in ``paper`` mode."""
    return (governor_enabled(config, args) and config["governor"]["action"] == "tdpa"
            and config["control"]["mode"] == "paper")


def start_governor(config: dict[str, Any], args: argparse.Namespace, model: TeleopModel,
                   program: str = "haptic-master", stream: TextIO | None = None,
                   ) -> tuple[MarginGovernor | None, int | None]:
    """The governor (None when not enabled) and ``None`` to go on, or :data:`EXIT_UNSTABLE`
    when the largest round trip the configured delay profiles reach is beyond the delay
    margin of the lowest gain and ``--allow-unstable`` was not given (with the ``tdpa``
    action the passivity layer covers any round trip, so nothing is refused). Raises
    :class:`~haptic.common.config.ConfigError` (``governor.action``)."""
    stream = stream if stream is not None else sys.stderr
    if not governor_enabled(config, args):
        return None, None
    switchable = tdpa_standby(config, args)
    governor = governor_for(model, config, tdpa_available=switchable)
    if switchable:
        print(f"{program}: governor (tdpa: the passivity layer switches on before the round "
              f"trip reaches {governor.settings.safety_factor:g} tau*(k)): "
              f"{governor.table.describe()}", file=stream, flush=True)
        return governor, None
    print(f"{program}: governor ({governor.settings.action}, usable while round trip <= "
          f"{governor.settings.safety_factor:g} tau*): {governor.table.describe()}",
          file=stream, flush=True)
    worst = round_trip_delay_s(config, getattr(args, "assumed_link_delay",
                                               DEFAULT_ASSUMED_LINK_DELAY_S),
                               "master", getattr(args, "peer_delay", None), "max")
    floor = governor.table.entries[-1].k
    if worst < governor.table.margin_s(floor):
        return governor, None
    if getattr(args, "allow_unstable", False):
        print(f"{program}: the configured delays reach {worst * 1e3:.2f} ms, beyond tau* of "
              f"every k down to {floor:g}; starting anyway (--allow-unstable)", file=stream,
              flush=True)
        return governor, None
    print(f"{program}: refusing to start: the configured delays reach {worst * 1e3:.2f} ms "
          f"round trip, beyond tau* of every k down to {floor:g} "
          f"({governor.table.margin_s(floor) * 1e3:.2f} ms); pass --allow-unstable to run it",
          file=stream, flush=True)
    return None, EXIT_UNSTABLE


def governor_step(governor: MarginGovernor, latest: object | None, first_sent_ns: int,
                  last_sent_ns: int, poll_ns: int, now_s: float) -> GovernorDecision:
    """One tick: the echo age of ``latest`` (the newest tool message) into the governor: the
    poll time ``poll_ns`` minus the echoed handle send time, both CLOCK_REALTIME ns on this
    host. An echo of no handle message this master sent (before ``first_sent_ns``, after
    ``last_sent_ns``: a faulty or forged slave's) is no round trip: it is counted once per
    message and not used, so it can neither hide the delay (a future echo read as zero round
    trip) nor invent one. ``now_s``: the tick's time, s."""
    echo_ns = getattr(latest, "echo_send_time_ns", 0) if latest is not None else 0
    if echo_ns > 0 and not first_sent_ns <= echo_ns <= last_sent_ns:
        if latest is not governor.last_invalid_echo:
            governor.last_invalid_echo = latest
            governor.invalid_echoes += 1
        echo_ns = 0
    age_s = (poll_ns - echo_ns) * 1e-9 if echo_ns > 0 else None
    return governor.update(now_s, age_s)
