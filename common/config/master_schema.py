"""Configuration schema of the master side: ``[master]`` and its sub-tables."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from haptic.common.config.fields import Field, Schema
from haptic.common.config.operator_spec import check_operator_spec


def _pair(values: Any) -> str | None:
    return None if len(values) == 2 else f"must list 2 values, x then y (got {len(values)})"


#: The handle hardware backends haptic.master registers (``[master] rig``); plain data so the
#: configuration does not import the backends (tests check it against the registry).
RIG_BACKENDS = ("can", "model", "sim", "sim-inproc")


def _rig_name(name: Any) -> str | None:
    return (None if name in RIG_BACKENDS
            else f"must be one of {', '.join(RIG_BACKENDS)} (got {name!r})")


def _existing_file(*suffixes: str) -> Any:
    """A check for a file key: empty (the packaged file) or an existing file ending in one of
    ``suffixes`` (what the reader behind it takes: cantools by .dbc, canopen by .eds/.dcf)."""

    def check(value: str) -> str | None:
        if not value:
            return None
        path = Path(value)
        if path.suffix.lower() not in suffixes:
            return f"must be a {' or '.join(suffixes)} file (got {value!r})"
        try:
            if path.is_file():
                return None
        except OSError as error:  # a name the file system cannot take
            return f"cannot read {value!r}: {error.strerror}"
        return f"no such file: {value!r}"

    return check


CAN_SCHEMA: Schema = {
    "interface": Field("str", "python-can interface of the real bus, e.g. socketcan, pcan."),
    "channel": Field("str", "python-can channel, e.g. can0."),
    "bitrate": Field("int", "CAN bitrate, bit/s.", minimum=10_000, maximum=1_000_000),
    "x_node_id": Field("int", "CANopen node id of the x-axis CiA 402 drive.", minimum=1,
                       maximum=127),
    "y_node_id": Field("int", "CANopen node id of the y-axis CiA 402 drive.", minimum=1,
                       maximum=127),
    "dbc_file": Field("str", "Force sensor DBC file; empty for the packaged one.",
                      check=_existing_file(".dbc")),
    "pdo_timeout_s": Field("float", "How long read() waits for the PDOs of a SYNC, s.",
                           minimum=0.0, exclusive_minimum=True),
    "sync_lead_s": Field("float", "The loop sends each cycle's SYNC this long before its "
                         "tick, while it waits for it, so the drives' and the sensor's answers "
                         "are there when the tick reads them, s (at most one period); 0: "
                         "read() sends it at the tick and waits. The sample-to-command delay "
                         "stays one SYNC.", minimum=0.0, maximum=0.01),
    "enable_timeout_cycles": Field("int", "SYNC cycles allowed for the CiA 402 enable "
                                   "sequence and SDO replies.", minimum=1),
    "lead_screw_pitch_m_per_rev": Field("float", "Lead-screw pitch, m per revolution.",
                                        minimum=0.0, exclusive_minimum=True),
    "encoder_counts_per_rev": Field("int", "Encoder counts per motor revolution (after "
                                    "quadrature), counts/rev.", minimum=1),
    "force_scale_N_per_count": Field("float_list", "Sensor scale per channel (x, y), N per "
                                     "count.", check=_pair),
    "force_offset_count": Field("float_list", "Sensor offset per channel (x, y), counts.",
                                check=_pair),
    "x_eds_file": Field("str", "EDS or DCF file of the x drive (configure() maps its PDOs "
                        "from it); empty for the packaged "
                        "master/hardware/eds/haptic_cia402_drive.eds.",
                        check=_existing_file(".eds", ".dcf")),
    "y_eds_file": Field("str", "EDS or DCF file of the y drive; empty for the packaged one.",
                        check=_existing_file(".eds", ".dcf")),
    "master_node_id": Field("int", "Node id of the master's heartbeat (the drives consume "
                            "it).", minimum=1, maximum=127),
    "heartbeat_period_s": Field("float", "Heartbeat producer period of the master and the "
                                "drives, s (0x1017 in ms).", minimum=0.001, maximum=65.0),
    "heartbeat_timeout_s": Field("float", "Heartbeat consumer time on both sides, s: a drive "
                                 "stops (0x6007 reaction) when the master's heartbeat is "
                                 "older, the master reports a drive's.", minimum=0.001,
                                 maximum=65.0),
    "rpdo_timeout_s": Field("float", "RPDO deadline on the drives (0x1400:05), s in SYNC "
                            "time; 0 off.", minimum=0.0, maximum=65.0),
    "following_error_window_m": Field("float", "Following error window of the drives "
                                      "(0x6065), m.", minimum=0.0, exclusive_minimum=True),
    "bus_load_limit": Field("float", "configure() refuses a cycle whose frames need more "
                            "than this fraction of Ts (worst-case bit stuffing).",
                            minimum=0.0, exclusive_minimum=True, maximum=1.0),
    "fd": Field("bool", "CAN FD: the cyclic frames (SYNC, PDOs, sensor) as FD frames with "
                "bit-rate switch; NMT, SDO, EMCY and heartbeat stay classical."),
    "data_bitrate": Field("int", "CAN FD data-phase bitrate, bit/s.", minimum=1_000_000,
                          maximum=12_000_000),
    "sync_counter_overflow": Field(
        "int", "SYNC counter (CiA 301 0x1019): the SYNC carries a counter 1..this value, "
        "written to every drive whose EDS has 0x1019 (none of them lacking it); 0 off.",
        minimum=0, maximum=240,
        check=lambda v: None if v != 1 else "must be 0 (off) or 2..240 (CiA 301 0x1019)"),
    "allow_no_drive_watchdog": Field(
        "bool", "Accept a drive whose EDS leaves it no drive-side watchdog: no heartbeat "
        "consumer (0x1016), no RPDO deadline (0x1400:05, or rpdo_timeout_s = 0) and no life "
        "guarding (0x100C/0x100D). Such a drive keeps following its last target when the "
        "master stalls; false (the default) refuses it at configure."),
}

def _emulator_interface(name: Any) -> str | None:
    if name == "virtual":
        return ("python-can's virtual bus does not cross processes; use unix_datagram or "
                "udp_multicast (or the in-process rig, rig = \"sim-inproc\")")
    return None if name else "must name a python-can interface, e.g. unix_datagram"


EMULATOR_SCHEMA: Schema = {
    "interface": Field("str", "python-can interface between the sim backend's CAN driver and "
                       "its emulator process (haptic-rig-sim): unix_datagram (this package's "
                       "Unix-socket bus, the fastest on one host) or udp_multicast.",
                       check=_emulator_interface),
    "channel": Field("str", "Channel on it: unix_datagram the bus's directory, empty for a "
                     "private temporary one per run; udp_multicast an IPv4 or IPv6 multicast "
                     "group, e.g. 239.74.163.2."),
    "port": Field("int", "UDP port of udp_multicast; 0 picks a free port per run, private to "
                  "it (two runs never hear each other).", minimum=0, maximum=65535),
    "start_timeout_s": Field("float", "How long configure() waits for the emulator process "
                             "to say it is ready, s.", minimum=0.0, exclusive_minimum=True),
}

SIM_SCHEMA: Schema = {
    "channel": Field("str", "python-can virtual bus channel of the in-process simulated rig "
                     "(rig sim-inproc)."),
    "pdo_timeout_s": Field("float", "How long read() waits for the simulated devices' "
                           "frames, s (they share the machine with the loop).", minimum=0.0,
                           exclusive_minimum=True),
    "operator": Field("str", "Operator model spec, kind:key=value,... (docs/master.md).",
                      check=check_operator_spec),
    "force_noise_std_N": Field("float", "Force sensor noise, standard deviation, N.",
                               minimum=0.0),
    "seed": Field("int", "Seed of the sensor noise generator.", minimum=0),
    "initial_position_m": Field("float_list", "Handle position at start (x, y), m.",
                                check=_pair),
    "emulator": EMULATOR_SCHEMA,
}

SAFETY_SCHEMA: Schema = {
    "force_limit_N": Field("float", "Forces (handle and tool) saturate at this magnitude "
                           "per axis, N.", minimum=0.0, exclusive_minimum=True),
    "force_trip_N": Field("float", "A measured handle force beyond this trips the safe "
                          "state, N.", minimum=0.0, exclusive_minimum=True),
    "velocity_limit_m_per_s": Field("float", "Handle command rate limit per axis, m/s.",
                                    minimum=0.0, exclusive_minimum=True),
    "velocity_trip_m_per_s": Field("float", "A measured handle speed beyond this trips the "
                                   "safe state, m/s.", minimum=0.0, exclusive_minimum=True),
    "workspace_min_m": Field("float_list", "Workspace box lower corner (x, y), m.",
                             check=_pair),
    "workspace_max_m": Field("float_list", "Workspace box upper corner (x, y), m.",
                             check=_pair),
    "workspace_trip_margin_m": Field("float", "A measured position this far outside the "
                                     "workspace trips the safe state, m.", minimum=0.0),
    "ramp_small_force_N": Field("float", "Force magnitude counted as small before forces "
                                "are enabled, N.", minimum=0.0, exclusive_minimum=True),
    "ramp_small_samples": Field("int", "Consecutive small-force samples needed before "
                                "forces are enabled.", minimum=1),
    "ramp_time_s": Field("float", "Forces ramp in linearly over this time once enabled, s.",
                         minimum=0.0),
}

#: [master.tool_input]: the master's bounds on received tool messages (master/tool_guard.py).
TOOL_INPUT_SCHEMA: Schema = {
    "force_trip_N": Field("float", "A received tool force beyond this on an axis is a fault "
                          "(below it the node saturates at force_limit_N), N.", minimum=0.0,
                          exclusive_minimum=True),
    "position_min_m": Field("float_list", "Lowest plausible tool position (x, y), m.",
                            check=_pair),
    "position_max_m": Field("float_list", "Highest plausible tool position (x, y), m.",
                            check=_pair),
    "velocity_trip_m_per_s": Field(
        "float", "A tool position that moved faster than this between two messages is a "
        "fault, m/s.", minimum=0.0, exclusive_minimum=True),
    "jump_margin_m": Field("float", "Allowance on top of the speed bound for a tool position "
                           "jump, m.", minimum=0.0),
    "clear_after_messages": Field("int", "Plausible tool messages in a row that clear a "
                                  "fault.", minimum=1),
    "jitter_allowance_s": Field(
        "float", "How much earlier than usual (delay shorter than usual) a tool message may "
        "arrive and its send-time difference still count in full in the jump bound, s.",
        minimum=0.0, maximum=1.0),
}

MASTER_SCHEMA: Schema = {
    "rig": Field("str", "Handle hardware by name: can (servo drives on a CAN bus), sim "
                 "(the simulated drives and sensor in their own process, haptic-rig-sim), "
                 "sim-inproc (the same devices on a thread of the master, virtual bus) or "
                 "model (the rig block, no bus).",
                 check=_rig_name),
    "can": CAN_SCHEMA,
    "sim": SIM_SCHEMA,
    "safety": SAFETY_SCHEMA,
    "tool_input": TOOL_INPUT_SCHEMA,
}
