"""``haptic-rig-sim``: the simulated rig's CAN devices (two CiA 402 drives and the force
sensor, with the scripted operator) as a process of their own on a bus that crosses processes.

The ``sim`` backend of ``haptic-master`` starts one per run on a bus private to the run; by
hand, start it first and point the master's ``can`` backend at the same bus (the emulator's
``[master.sim.emulator]`` interface, unix_datagram by default; without a channel it serves
the directory ``$TMPDIR/haptic-rig-sim``, or python-can's udp_multicast group 239.74.163.2
port 43113)::

    haptic-rig-sim --operator constant:fx=1,onset=0.05 &
    haptic-master --rig can --can-interface unix_datagram --can-channel /tmp/haptic-rig-sim \
        --no-link --duration 2

It runs under SCHED_BATCH (its wake-ups never preempt the loops it shares the machine with;
``--scheduling normal``: normal scheduling, as the ``sim`` backend starts it on the master's own
loop CPUs, where batching only delays its answer; ``--scheduling fifo --rt-priority N``:
SCHED_FIFO, as the backend starts it one above a master loop in SCHED_FIFO on those CPUs),
prints one line starting
``haptic-rig-sim: ready`` when it answers frames, serves until
``--duration`` or SIGINT/SIGTERM (exit status 0), and prints one line when it stops. Exit
status 1 when the bus cannot open, 2 for an invalid option or configuration (one line naming
it).
"""

from __future__ import annotations

import argparse
import math
import sys
from typing import Any

from haptic.common.config import ConfigError, exit_on_config_error, load_config, override
from haptic.common.config.runner_schema import MAX_FIFO_PRIORITY
from haptic.common.runtime.console import script_description
from haptic.common.runtime.warp_init import init_warp
from haptic.master.settings import emulator_settings
from haptic.master.simulated_rig.can_devices import SimulatedCanRig
from haptic.master.simulated_rig.rig_emulator import (
    DEFAULT_CHANNELS,
    DEFAULT_UDP_PORT,
    StopRequest,
    run_emulator,
    use_batch_scheduling,
    use_fifo_scheduling,
)

# flag dest -> (flag, key)
_FLAGS = {
    "can_interface": ("--can-interface", "master.sim.emulator.interface"),
    "can_channel": ("--can-channel", "master.sim.emulator.channel"),
    "can_port": ("--can-port", "master.sim.emulator.port"),
    "operator": ("--operator", "master.sim.operator"),
}


def build_parser() -> argparse.ArgumentParser:
    """The command line."""
    parser = argparse.ArgumentParser(prog="haptic-rig-sim", description=script_description(__doc__),
                                     allow_abbrev=False)
    parser.add_argument("--config", metavar="FILE", help="TOML configuration (over the "
                        "defaults): [model], [master.can], [master.sim] and its emulator table")
    parser.add_argument("--can-interface", metavar="NAME",
                        help="python-can interface ([master.sim.emulator] interface; default "
                        "unix_datagram, or udp_multicast)")
    parser.add_argument("--can-channel", metavar="CHANNEL",
                        help="channel on it ([master.sim.emulator] channel); default: for "
                        f"unix_datagram the directory {DEFAULT_CHANNELS.get('unix_datagram')}, "
                        f"for udp_multicast the group {DEFAULT_CHANNELS.get('udp_multicast')}")
    parser.add_argument("--can-port", metavar="PORT", type=int,
                        help="udp_multicast UDP port ([master.sim.emulator] port; when that is "
                        f"0, python-can's default {DEFAULT_UDP_PORT})")
    parser.add_argument("--operator", metavar="SPEC",
                        help="simulated operator ([master.sim] operator), e.g. "
                        "regulate:fx=3.6,onset=0.2")
    parser.add_argument("--operator-waits-for-lamp", action="store_true",
                        help="start the operator's script at the master's first ready-lamp "
                        "frame (the sim backend passes it) instead of the first SYNC")
    parser.add_argument("--duration", metavar="S", type=float,
                        help="serve for S seconds (default: until SIGINT or SIGTERM)")
    parser.add_argument("--scheduling", choices=("batch", "normal", "fifo"), default="batch",
                        help="batch (default): SCHED_BATCH, its wake-ups never preempt the "
                        "loops on its CPUs; normal: normal scheduling (on CPUs of its own, or "
                        "the master's loop CPUs, where it answers while the loop sleeps); "
                        "fifo: SCHED_FIFO at --rt-priority (on the CPU of a master loop in "
                        "SCHED_FIFO, one above it)")
    parser.add_argument("--rt-priority", metavar="N", type=int,
                        help="SCHED_FIFO priority 1-99 of --scheduling fifo (required there)")
    parser.add_argument("--parent-pid", metavar="PID", type=int,
                        help="also stop when process PID is no longer this one's parent "
                        "(the sim backend passes its own)")
    return parser


def _configure(args: argparse.Namespace) -> tuple[SimulatedCanRig, dict[str, Any]]:
    """The devices of the validated configuration and the bus options; :class:`ConfigError`
    naming the flag (and its key) or the key."""
    config = load_config(args.config)
    if args.can_port is not None and not 1 <= args.can_port <= 65535:
        raise ConfigError("--can-port", f"must be a UDP port, 1 to 65535 (got {args.can_port})")
    for dest, (flag, key) in _FLAGS.items():
        value = getattr(args, dest)
        if value is None:
            continue
        try:
            config = override(config, key, value)
        except ConfigError as error:
            raise ConfigError(f"{flag} ({key})", str(error).removeprefix(f"{key}: ")) from None
    table = config["master"]["sim"]["emulator"]
    if not table["channel"]:  # by hand: the interface's default bus
        default = DEFAULT_CHANNELS.get(table["interface"], "")
        config = override(config, "master.sim.emulator.channel", default)
    try:
        emulator = emulator_settings(config["master"]["sim"]["emulator"])
    except ConfigError as error:
        if args.can_channel is None and args.can_interface is None:
            raise
        message = str(error).removeprefix(f"{error.key}: ")
        raise ConfigError(f"--can-channel ({error.key})", message) from None
    if args.duration is not None and not (args.duration > 0.0 and math.isfinite(args.duration)):
        raise ConfigError("--duration", f"must be a finite number > 0 s (got {args.duration})")
    if args.scheduling == "fifo" and not (
            args.rt_priority is not None and 1 <= args.rt_priority <= MAX_FIFO_PRIORITY):
        raise ConfigError("--rt-priority", f"--scheduling fifo needs a priority 1-"
                          f"{MAX_FIFO_PRIORITY} (got {args.rt_priority})")
    if args.rt_priority is not None and args.scheduling != "fifo":
        raise ConfigError("--rt-priority", "applies to --scheduling fifo only")
    if args.parent_pid is not None and args.parent_pid < 1:
        raise ConfigError("--parent-pid", f"must be a process id >= 1 (got {args.parent_pid})")
    try:
        rig = SimulatedCanRig.from_config(config, emulator.channel,
                                          operator_waits_for_lamp=args.operator_waits_for_lamp)
    except ValueError as error:  # ConfigError names its key; the rig model's name the axis
        if isinstance(error, ConfigError):
            raise
        raise ConfigError("model", str(error)) from None
    return rig, emulator.bus_options(emulator.channel, emulator.port or DEFAULT_UDP_PORT)


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit status: 0 after SIGINT/SIGTERM, ``--duration`` or the end
    of ``--parent-pid``; 1 when the bus cannot open; 2 for a configuration error (one line)."""
    args = build_parser().parse_args(argv)
    init_warp()  # the devices' rig model is Warp's, on its CPU device
    with exit_on_config_error():
        rig, bus_options = _configure(args)
    stop = StopRequest(args.duration, args.parent_pid)
    stop.install()
    warning = (use_batch_scheduling() if args.scheduling == "batch"
               else use_fifo_scheduling(args.rt_priority) if args.scheduling == "fifo"
               else None)
    if warning is not None:
        print(f"haptic-rig-sim: {warning}", file=sys.stderr)
    return run_emulator(rig, bus_options, stop)


if __name__ == "__main__":
    raise SystemExit(main())
