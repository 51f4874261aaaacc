#!/usr/bin/env python3
"""Mutation score of the safety-critical modules: how many small planted bugs the tests catch.

Each mutant is one small change of one module's source (``<`` -> ``<=``, ``+`` -> ``-``, a
number plus one, ``and`` -> ``or``, a condition negated, ...; cosmic-ray's operators, a curated
one-replacement-per-site subset, see :data:`OPERATORS`). The module's tests (:data:`MODULES`)
run against it; the mutant is *killed* when they fail (or crash, or exceed the time limit),
*survived* when they pass. The score is killed / (killed + survived).

Why not ``cosmic-ray exec`` or ``mutmut run`` (docs/testing.md): cosmic-ray's executor
writes each mutant into the working tree and starts the test command afresh, paying about
5 s of imports (Warp, SciPy, python-control, Zenoh) per mutant for some 3000 mutants of its
full operator set; mutmut 3 copies the sources into ``mutants/`` with trampolines keyed by
module names derived from the file paths (``master.node``, where the package-dir mapping
makes it ``haptic.master.node``) and skips decorated functions, i.e. every Warp kernel.
So this script uses cosmic-ray's operators to make the mutants and runs them itself: a parent
process imports the heavy libraries once and forks one child per mutant; the child serves the
mutated source for the one module (an import hook, plus linecache so that Warp compiles the
mutated kernel source) and runs pytest on the module's tests. Nothing is written into the
source tree. Warp kernels compile into a private cache that is deleted at the end.

Usage::

    python bench/mutation_score.py                  # every module, a table and the time taken
    python bench/mutation_score.py --module common/runtime/watchdog.py --survivors
    python bench/mutation_score.py --json           # {"modules": {path: {...}}, "total_score"}

Adding a module is one line in :data:`MODULES`: its path and the tests that should catch its
mutants. A line ending in ``# pragma: no mutate`` is never mutated (for code whose mutants
are equivalent by construction; docs/testing.md lists each).
"""

from __future__ import annotations

import argparse
import ast
import difflib
import json
import os
import shutil
import signal
import sys
import tempfile
import time
import tomllib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent



@dataclass(frozen=True)
class Target:
    """A module's tests (the fastest first: pytest stops at the first failure) and, for a
    module whose mutants are slow (a Warp kernel recompiles for each, about 2 s here), the
    sampling: every ``every``-th mutant in source order unless ``--all``."""

    tests: tuple[str, ...]
    every: int = 1


_NODE_TESTS = ("tests/master/test_node_limits.py", "tests/master/test_node.py",
               "tests/master/test_node_kernel.py")
#: The modules under mutation. Adding one is one line: its path and the tests that should
#: catch its mutants.
MODULES: dict[str, Target] = {
    "common/runtime/watchdog.py": Target(("tests/common/test_watchdog.py",)),
    "master/node.py": Target(_NODE_TESTS),
    "master/node_kernels.py": Target(_NODE_TESTS, every=3),
    "common/wire/messages.py": Target(("tests/common/test_message_limits.py",
                                  "tests/common/test_messages.py",
                                  "tests/common/test_receive.py")),
    "common/wire/receive.py": Target(("tests/common/test_receive_filter.py",
                                 "tests/common/test_receive_window.py",
                                 "tests/common/test_receive_limits.py",
                                 "tests/common/test_receive.py",
                                 "tests/common/test_message_limits.py",
                                 "tests/common/test_messages.py")),
    "common/model/synthesis.py": Target(("tests/common/test_synthesis.py",)),
    "master/supervisor.py": Target(("tests/master/test_supervisor.py",)),
    "slave_sim/supervisor.py": Target(("tests/slave_sim/test_supervisor.py",
                                       "tests/wire/test_supervisor_policy.py")),
    "slave_sim/input_guard.py": Target(("tests/slave_sim/test_input_guard_limits.py",
                                        "tests/wire/test_input_guard.py",
                                        "tests/wire/test_send_clock.py")),
    "master/tool_guard.py": Target(("tests/master/test_tool_guard_limits.py",
                                    "tests/wire/test_send_clock.py",
                                    "tests/wire/test_tool_guard.py")),
    "common/wire/send_clock.py": Target(("tests/wire/test_send_clock.py",
                                         "tests/slave_sim/test_quiet_kernel.py")),
    "slave_sim/resync.py": Target(("tests/slave_sim/test_resync.py",)),
    "common/wire/phase_lock.py": Target(("tests/common/test_phase_lock_limits.py",
                                         "tests/common/test_phase_lock.py",
                                         "tests/slave_sim/test_phase_lock_config.py")),
    "common/wire/passivity_link.py": Target(("tests/common/test_passivity_link.py",)),
    "common/model/passivity.py": Target(("tests/common/test_passivity_controllers.py",
                                         "tests/common/test_passivity_limits.py",
                                         "tests/common/test_passivity.py")),
    "master/margin_governor.py": Target(("tests/master/test_margin_governor_limits.py",
                                         "tests/master/test_margin_governor.py")),
    "common/model/work_area.py": Target(("tests/common/test_work_area.py",
                                         "tests/slave_sim/test_tool_wall.py")),
    "master/hardware/force_sensor.py": Target(("tests/master/test_force_sensor_limits.py",
                                               "tests/master/test_force_sensor.py")),
    "master/hardware/cia402.py": Target(("tests/master/test_cia402_limits.py",
                                         "tests/master/test_cia402.py")),
    "master/hardware/unix_can.py": Target(("tests/master/test_unix_can_limits.py",
                                           "tests/master/test_unix_can.py")),
    "common/config/loader.py": Target(("tests/common/test_config_limits.py",
                                       "tests/common/test_config.py")),
    "common/runtime/inert.py": Target(("tests/common/test_inert_limits.py",
                                       "tests/wire/test_inert.py")),
    "common/config/scenario.py": Target(("tests/slave_sim/test_scenario_limits.py",
                                         "tests/slave_sim/test_scenario.py")),
    "common/records/recording.py": Target(("tests/common/test_recording_limits.py",
                                           "tests/common/test_recording_damage.py",
                                           "tests/common/test_recorder.py")),
    "slave_sim/pacing.py": Target(("tests/slave_sim/test_pacing_limits.py",
                                   "tests/slave_sim/test_pacing.py")),
    "common/wire/auth.py": Target(("tests/wire/test_auth_units.py", "tests/wire/test_auth.py")),
    "common/model/clay_contact.py": Target(("tests/slave_sim/test_clay.py",
                                      "tests/lockstep/test_clay_analysis.py")),
    "slave_sim/clay/sim.py": Target(("tests/slave_sim/test_clay_limits.py",
                                 "tests/slave_sim/test_clay.py")),
    "slave_sim/clay/clay_kernels.py": Target(("tests/slave_sim/test_clay_limits.py",
                                         "tests/slave_sim/test_clay.py"), every=3),
    "common/wire/injection.py": Target(("tests/common/test_injection_limits.py",
                                        "tests/common/test_delay_profile.py",
                                        "tests/common/test_receive.py")),
    "common/records/heightmap_codec.py": Target(("tests/common/test_heightmap_codec.py",
                                                 "tests/slave_sim/test_clay_view.py")),
    "master/hardware/can_driver.py": Target(("tests/master/test_can_driver_cycle.py",
                                             "tests/master/test_can_driver_configure.py",
                                             "tests/master/test_can_driver_sdo.py",
                                             "tests/master/test_can_commissioning.py",
                                             "tests/master/test_sync_lead.py",
                                             "tests/master/test_sim_rig.py")),
    "master/hardware/drive_device.py": Target(("tests/master/test_drive_device_limits.py",
                                               "tests/master/test_can_commissioning.py",
                                               "tests/master/test_sim_rig.py")),
}

_BINARY = (("Add", "Sub"), ("Sub", "Add"), ("Mul", "Div"), ("Div", "Mul"), ("FloorDiv", "Div"),
           ("Mod", "FloorDiv"), ("Pow", "Mul"), ("BitOr", "BitAnd"), ("BitAnd", "BitOr"),
           ("BitXor", "BitOr"), ("LShift", "RShift"), ("RShift", "LShift"))
_COMPARISON = (("Lt", "LtE"), ("LtE", "Lt"), ("Gt", "GtE"), ("GtE", "Gt"), ("Eq", "NotEq"),
               ("NotEq", "Eq"), ("Is", "IsNot"), ("IsNot", "Is"))
#: cosmic-ray operators used, one plausible replacement per site (its full set replaces each
#: operator by every other one: five times the mutants, mostly trivially killed).
OPERATORS: tuple[str, ...] = (
    *(f"core/ReplaceBinaryOperator_{a}_{b}" for a, b in _BINARY),
    *(f"core/ReplaceComparisonOperator_{a}_{b}" for a, b in _COMPARISON),
    "core/NumberReplacer",  # +1 only (see _keep)
    "core/ReplaceTrueWithFalse", "core/ReplaceFalseWithTrue",
    "core/ReplaceAndWithOr", "core/ReplaceOrWithAnd", "core/AddNot",
    "core/ReplaceUnaryOperator_Delete_Not", "core/ReplaceUnaryOperator_Delete_USub",
    "core/ReplaceBreakWithContinue", "core/ReplaceContinueWithBreak",
    "core/ZeroIterationForLoop", "core/ExceptionReplacer",
)
#: Imported once in the parent, before forking (a child pays none of it).
PRELOAD = ("numpy", "scipy.linalg", "scipy.signal", "control", "msgpack", "zenoh", "warp",
           "hypothesis", "pytest", "mcap", "can", "canopen", "cantools", "matplotlib")
PRAGMA = "# pragma: no mutate"

#: Mutants that cannot change behaviour, each with the reason: (module, line before, line
#: after, why), the lines stripped. They are not run and not counted; docs/testing.md shows
#: this table (``--equivalents``).
_REPR = "repr of a private field only: no behaviour reads a repr"
_CUDA = ("CUDA-only path (the pinned staging buffers and their copies): not run on the CPU "
         "device, where the step uses zero-copy views; on a GPU machine "
         "test_clay_limits.py::test_cuda_device_matches_numpy runs it")
EQUIVALENT: tuple[tuple[str, str, str, str], ...] = (
    *((module, "_plausible_run: int = 0", "_plausible_run: int = 1",
       "read only after a fault, and every fault sets it to 0 first")
      for module in ("slave_sim/input_guard.py", "master/tool_guard.py")),
    *(("common/wire/send_clock.py", f"{name}: int = 0", f"{name}: int = 1",
       "read only for a message of the epoch an accepted message set, which set it too")
      for name in ("credited_ns", "received_ns", "lead_ns")),
    ("slave_sim/resync.py",
     "scale = np.where(distance > max_step, max_step / distance, 1.0)",
     "scale = np.where(distance >= max_step, max_step / distance, 1.0)",
     "at distance == max_step the scale max_step / distance is 1.0"),
    ("slave_sim/resync.py",
     "for column, value in zip(POSITION_COLUMNS, position.T, strict=True):",
     "for column, value in zip(POSITION_COLUMNS, position.T, strict=False):",
     "two position columns and a (lanes, 2) position: the lengths always match"),
    ("master/margin_governor.py", "while samples and samples[-1][1] <= value:",
     "while samples and samples[-1][1] < value:",
     "an equal older sample kept in front of the newer one: the window's maximum is the same "
     "value until both have left it"),
    ("master/margin_governor.py",
     "return time_s - self._above_since >= self.settings.confirm_s - 1e-12",
     "return time_s - self._above_since > self.settings.confirm_s - 1e-12",
     "the 1e-12 s slack already takes confirm_s itself; only a time 1e-12 s short of it "
     "differs"),
    ("common/wire/phase_lock.py", "step = -1 if error > 0 else 1",
     "step = -1 if error >= 0 else 1",
     "an error of 0 is inside every deadband (-0 <= 0 <= 0) and never reaches this line"),
    ("common/wire/passivity_link.py", "if value > port.peer_sent_J[0]:  # NaN compares False: "
     "nothing noted", "if value >= port.peer_sent_J[0]:  # NaN compares False: nothing noted",
     "an equal value assigns the same value"),
    ("common/model/passivity.py",
     "known = np.all(np.isfinite(gap_m), axis=1) & (rate_per_s > 0.0)",
     "known = np.all(np.isfinite(gap_m), axis=1) & (rate_per_s >= 0.0)",
     "a rate of 0 makes every finite gap's step gap x 0 = 0, the step of a lane not known"),
    ("master/hardware/force_sensor.py",
     "for value, (low, high) in zip(ordered, layout.limits, strict=True):",
     "for value, (low, high) in zip(ordered, layout.limits, strict=False):",
     "both are built from the layout's signals, one entry each: the lengths always match"),
    ("master/hardware/force_sensor.py",
     "values = dict(zip(layout.names, layout.codec.unpack_from(payload), strict=True))",
     "values = dict(zip(layout.names, layout.codec.unpack_from(payload), strict=False))",
     "the struct has one field per name: the lengths always match"),
    ("master/hardware/cia402.py", "pairs = zip(mapping, values, strict=True)",
     "pairs = zip(mapping, values, strict=False)",
     "the lengths are checked just before (ValueError naming both)"),
    ("master/hardware/cia402.py", "for variable, size in zip(mapping, sizes, strict=True):",
     "for variable, size in zip(mapping, sizes, strict=False):",
     "the sizes are built from the mapping, one each: the lengths always match"),
    *(("master/hardware/cia402.py", "(0x4F, 0x08, DriveState.FAULT),", after,
       "the last pattern: a word that no pattern matches is read as a fault too (a reserved "
       "code), so the fault's own pattern decides nothing")
      for after in ("( 80, 0x08, DriveState.FAULT),", "(0x4F, 9, DriveState.FAULT),")),
    ("master/hardware/unix_can.py",
     "def _message(frame_id: int, flags: int, data: bytes, timestamp: float = 0.0,",
     "def _message(frame_id: int, flags: int, data: bytes, timestamp: float = 1.0,",
     "only messages to send take the default, and python-can's send ignores a timestamp"),
    ("master/hardware/unix_can.py",
     "self._directory_fd = os.open(self.directory, os.O_RDONLY | os.O_DIRECTORY)",
     "self._directory_fd = os.open(self.directory, os.O_RDONLY & os.O_DIRECTORY)",
     "O_RDONLY is 0 and the path is a directory (mkdir made it or refused): the same open"),
    *(("master/hardware/unix_can.py", "self._directory_mtime_ns = -1", after,
       "a sentinel for no listing yet: no directory's modification time is 1 or -2 ns")
      for after in ("self._directory_mtime_ns = - 2", "self._directory_mtime_ns = 1")),
    *(("master/hardware/unix_can.py", "time.time_ns() - mtime_ns > RESCAN_S * 1e9):", after,
       "a difference of whole ns against 5e7 ns: a tie or 0.05 ns more lists the same members "
       "once more or once less")
      for after in ("time.time_ns() - mtime_ns > RESCAN_S * 1000000001.0):",
                    "time.time_ns() - mtime_ns >= RESCAN_S * 1e9):")),
    ("master/hardware/unix_can.py", "if deadline is not None and now >= deadline:",
     "if deadline is not None and now > deadline:",
     "at now == deadline the select that follows waits 0 s and gives the same None"),
    ("master/hardware/unix_can.py",
     "return self._socket.recv(_MAX_DATAGRAM + 1)  # one more: a longer one shows",
     "return self._socket.recv(_MAX_DATAGRAM + 2)  # one more: a longer one shows",
     "any buffer longer than the largest burst shows a longer datagram, which is dropped"),
    ("master/hardware/unix_can.py", "return None, False", "return None, True",
     "python-can reads the already-filtered flag only with a message"),
    ("common/runtime/inert.py", "_inert_from_s: float = 0.0", "_inert_from_s: float = 1.0",
     "read only while inert, and becoming inert sets it first"),
    ("common/records/recording.py", "break", "continue",
     "the footer is a file's last record: the stream reader's records end with it"),
    ("master/node.py",
     "for lane, code in sorted(zip(tripped.tolist(), codes[tripped].tolist(), strict=True),",
     "for lane, code in sorted(zip(tripped.tolist(), codes[tripped].tolist(), strict=False),",
     "the codes are indexed by the tripped lanes themselves: the lengths always match"),
    ("master/node.py", "for lane, value in zip(lanes, values, strict=True)",
     "for lane, value in zip(lanes, values, strict=False)",
     "both lists come from the same flagged lanes: the lengths always match"),
    ("master/supervisor.py",
     "flags = 0 if tool is None else int(tool.flags)  # int arithmetic: IntFlag's costs 1 us",
     "flags = 1 if tool is None else int(tool.flags)  # int arithmetic: IntFlag's costs 1 us",
     "bit 0 is no flag the supervisor reads (FORCES_ENABLED 2, WORK_AREA_STOP 16), and "
     "without a tool the slave cannot have stopped"),
    ("master/margin_governor.py", "if rtt > self.max_rtt_s:", "if rtt >= self.max_rtt_s:",
     "an equal round trip assigns the same value"),
    ("master/margin_governor.py", "if k < self.min_gain_used_k:",
     "if k <= self.min_gain_used_k:", "an equal gain assigns the same value"),
    ("common/wire/auth.py",
     "descriptor = os.open(file, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)",
     "descriptor = os.open(file, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 385)",
     "the os.chmod(file, 0o600) that follows sets the mode either way (it is there for a "
     "file that already existed)"),
    ("master/node.py", "@dataclass(eq=False)", "@dataclass(eq=True)",
     "nothing compares or hashes node states (identity is what the programs keep)"),
    *(("master/node.py", f"{name}: {kind} = field(default={default}, repr=False){tail}",
       f"{name}: {kind} = field(default={default}, repr=True){tail}", _REPR)
      for name, kind, default, tail in (
          ("_kernel", "Any", "None", "  # the recorded launch over these buffers"),
          ("_trip_code", "np.ndarray | None", "None", ""),
          ("_event_bits", "np.ndarray | None", "None", ""),
          ("_event_count", "np.ndarray | None", "None", ""),
          ("_buffers", "tuple", "()", "  # keeps the Warp arrays alive"),
          ("_passivity_kernel", "Any", "None", ""))),
    *(("master/node.py", "if passivity is not None:", after,
       "only when the passivity kernel's module is compiled: wp.launch loads it at activate if "
       "it was not preloaded, and preloading it needlessly changes nothing")
      for after in ("if passivity is None:", "if not passivity is not None:")),
    ("master/node.py", "if per_lane and matrices[0].shape[0] != lanes:",
     "if per_lane and matrices[ 1].shape[0] != lanes:",
     "A and B are both (lanes, ., .): either's shape[0] is the lane count"),
    ("master/node.py", 'raise ValueError(f"compensator stacked for {matrices[0].shape[0]} lanes, "',
     'raise ValueError(f"compensator stacked for {matrices[ 1].shape[0]} lanes, "',
     "A and B are both (lanes, ., .): the message names the same count"),
    ("master/node.py", "used = buffer((lanes, 4), f64)", "used = buffer((lanes, 5), f64)",
     "a fifth column nobody writes or reads: the views take columns 0:2 and 2:4"),
    ("master/node.py",
     "handle_force_used_N=used_view[:, 0:2], tool_force_used_N=used_view[:, 2:4],",
     "handle_force_used_N=used_view[:, 0:2], tool_force_used_N=used_view[:, 2: 5],",
     "the buffer has 4 columns: 2:5 is 2:4"),
    ("master/node.py",
     "event_count = buffer((2,), i32)  # lanes with an event, lanes that tripped",
     "event_count = buffer(( 3,), i32)  # lanes with an event, lanes that tripped",
     "a third counter nobody uses"),
    ("master/node.py", "inputs[:, 4:6] = tool_force_recv_N", "inputs[:, 4: 7] = tool_force_recv_N",
     "the buffer has 6 columns: 4:7 is 4:6"),
    ("master/node.py", "counts[0] = counts[1] = 0", "counts[0] = counts[1] = 1",
     "the events are decoded from the per-step codes: a non-zero count only decodes a step "
     "without events, or scans for trips where there are none (time, not behaviour)"),
    ("master/node.py", "counts[0] = counts[1] = 0", "counts[ 1] = counts[1] = 0",
     "the events count never cleared: every later step is decoded, those without events "
     "to nothing (time, not behaviour)"),
    ("master/node_kernels.py", "wp.atomic_add(event_count, 0, 1)",
     "wp.atomic_add(event_count, 0, 2)",
     "the count is only tested for zero, and reset by the node after each decoding"),
    ("master/node_kernels.py", "wp.atomic_add(event_count, 1, 1)",
     "wp.atomic_add(event_count, 1, 2)",
     "the trip count is only tested for zero, and reset by the node after each decoding"),
    ("master/node_kernels.py", "ENABLE_BIT = 8", "ENABLE_BIT = 9",
     "any bit above the eight limit bits works: the kernel sets it, node.py reads it, both "
     "through the constant"),
    ("master/node_kernels.py", "COMPENSATOR_INPUT_COUNT = 4", "COMPENSATOR_INPUT_COUNT = 5",
     "a documentation constant: no code reads it"),
    ("master/node_kernels.py", "code = TRIP_WORKSPACE * 2 + 1\nif code >= 0:",
     "if code > 0:",
     "code 0 (a non-finite handle force, x) is set and acted on in the first block, which "
     "skips this one; the codes set here are 6 and above"),
    ("master/node_kernels.py", "code = wp.int32(-1)", "code = wp.int32(- 2)",
     "'no trip' is any negative code: every reader tests code >= 0"),
    ("master/node_kernels.py", "code = TRIP_NON_FINITE_FORCE * 2",
     "code = TRIP_NON_FINITE_FORCE * 3", "TRIP_NON_FINITE_FORCE is 0: 0 * 3 == 0 * 2"),
    ("master/node_kernels.py", "code = TRIP_NON_FINITE_FORCE * 2",
     "code = TRIP_NON_FINITE_FORCE / 2", "TRIP_NON_FINITE_FORCE is 0: 0 / 2 == 0 * 2"),
    ("common/wire/messages.py",
     "_packer = msgpack.Packer(use_bin_type=True, use_single_float=False)",
     "_packer = msgpack.Packer(use_bin_type=False, use_single_float=False)",
     "use_bin_type only changes how bytes objects pack: a message packs none (integers and "
     "floats only)"),
    ("common/model/synthesis.py",
     "return 0 if nonzero.size == 0 else len(polynomial) - 1 - int(nonzero[-1])",
     "return 1 if nonzero.size == 0 else len(polynomial) - 1 - int(nonzero[-1])",
     "only called on non-zero polynomials (the zero numerator returns earlier)"),
    ("common/wire/receive.py",
     "seq_state = self._seq = _Sequence(message.epoch, message.seq, message.seq - 1, 0)",
     "seq_state = self._seq = _Sequence(message.epoch, message.seq, message.seq - 1, 1)",
     "the highest send time starts below any real one (ns since 1970) either way"),
    ("common/wire/receive.py", "delivery_ns = arrival_ns if arrival_ns > target_ns else target_ns",
     "delivery_ns = arrival_ns if arrival_ns >= target_ns else target_ns",
     "when they are equal both branches give the same time"),
    ("common/wire/receive.py", "if send_ns > seq_state.highest_send_ns:",
     "if send_ns >= seq_state.highest_send_ns:", "when equal the assignment changes nothing"),
    ("common/wire/injection.py", "self._uniforms = np.empty(0)\nself._next = 0", "self._next = 1",
     "the buffer starts empty, so the first draw refills it and sets _next to 0 before _next "
     "is used as an index; nothing else reads _next"),
    ("common/wire/injection.py", "if target < self._last_target_ns:",
     "if target <= self._last_target_ns:", "when equal the assignment changes nothing"),
    ("master/hardware/drive_device.py",
     "self.node.sdo.on_request(cia402.SDO_RX_BASE + self.node_id, bytearray(data), 0.0)",
     "self.node.sdo.on_request(cia402.SDO_RX_BASE - self.node_id, bytearray(data), 0.0)",
     "canopen's SdoServer.on_request never reads its can_id: it decodes the request alone"),
    ("master/hardware/drive_device.py",
     "self.node.sdo.on_request(cia402.SDO_RX_BASE + self.node_id, bytearray(data), 0.0)",
     "self.node.sdo.on_request(cia402.SDO_RX_BASE + self.node_id, bytearray(data), 1.0)",
     "canopen's SdoServer.on_request never reads its timestamp"),
    ("master/hardware/drive_device.py", "if indices == (0x6041, 0x6064):  # the loop's mapping",
     "if indices == ( 24642, 0x6064):  # the loop's mapping",
     "a shortcut for the loop's mapping: the general path packs the same statusword and "
     "position into the same bytes"),
    ("master/hardware/drive_device.py", "if indices == (0x6041, 0x6064):  # the loop's mapping",
     "if indices == (0x6041, 24677):  # the loop's mapping",
     "a shortcut for the loop's mapping: the general path packs the same statusword and "
     "position into the same bytes"),
    ("master/hardware/drive_device.py",
     "return dict(zip(self._rpdo_indices, codec.unpack(data), strict=True))",
     "return dict(zip(self._rpdo_indices, codec.unpack(data), strict=False))",
     "the struct has one field per mapped object, so the lengths always match"),
    ("master/hardware/drive_device.py",
     "def send_message(self, can_id: int, data: bytes, remote: bool = False) -> None:",
     "def send_message(self, can_id: int, data: bytes, remote: bool = True) -> None:",
     "remote is deleted unread (SDO replies are data frames) and canopen's server never "
     "passes it"),
    ("common/wire/receive.py", "if not pending or pending[0][0] > now_ns:",
     "if not pending or pending[0][ 1] > now_ns:",
     "an early exit only: the loop below checks the delivery time itself and returns None "
     "when nothing is due"),
    ("common/wire/receive.py", "newest_delivery_ns = 0", "newest_delivery_ns = 1",
     "overwritten with the first message handed over; read only when there is one"),
    ("common/wire/receive.py", "if seq <= seq_state.delivered_seq:",
     "if seq < seq_state.delivered_seq:",
     "a sequence number is pending at most once (accept drops duplicates), so the one "
     "delivered is never pending again"),
    ("common/wire/receive.py", "delivered_seq: int = -1", "delivered_seq: int = - 2",
     "sequence numbers are >= 0: any negative start lies below all of them"),
    ("common/wire/receive.py", "if skipped < SEQUENCE_WINDOW else 1",
     "if skipped <= SEQUENCE_WINDOW else 1",
     "at skipped == SEQUENCE_WINDOW, (bits << SEQUENCE_WINDOW | 1) & _WINDOW_MASK is 1: the "
     "shifted bits all lie at or above SEQUENCE_WINDOW, which the mask clears"),
    ("common/wire/receive.py", "send_ns - seq_state.highest_send_ns, 0) * 1e-9:",
     "send_ns - seq_state.highest_send_ns, 1) * 1e-9:",
     "the same for an advance of 1 ns or more; for none, the limit is 64 against 64 + 2e-5, "
     "and the integer advance of the sequence number exceeds both or neither"),
    ("common/wire/messages.py",
     "_packer = msgpack.Packer(use_bin_type=True, use_single_float=False)",
     "_packer = msgpack.Packer(use_bin_type=True, use_single_float=True)",
     "the packer packs only integers (version, kind, epoch, seq, echo) and array headers; "
     "every payload float is written by struct as 0xcb and a float 64 (_HANDLE_BODY, "
     "_TOOL_BODY), so use_single_float is never consulted"),
    ("common/wire/messages.py",
     "fields = _unpackb(payload, use_list=True, raw=False, strict_map_key=True)",
     "fields = _unpackb(payload, use_list=True, raw=True, strict_map_key=True)",
     "no valid message holds a string: as str or as bytes, it is refused as not a number"),
    ("common/wire/messages.py",
     "fields = _unpackb(payload, use_list=True, raw=False, strict_map_key=True)",
     "fields = _unpackb(payload, use_list=True, raw=False, strict_map_key=False)",
     "no valid message holds a map: whatever its keys, it is refused"),
    ("slave_sim/clay/sim.py", "@dataclass(eq=False)", "@dataclass(eq=True)",
     "nothing compares or hashes clay states (identity is what the callers keep)"),
    ("slave_sim/clay/sim.py",
     "contact_ready: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))",
     "contact_ready: np.ndarray = field(default_factory=lambda: np.zeros( 1, bool))",
     "every ClayState is made by _ClayBase._new_state, which sets contact_ready to "
     "zeros(lanes): the default is never used"),
    ("slave_sim/clay/sim.py", "state.direction = np.zeros((lanes, 2))",
     "state.direction = np.zeros((lanes, 3))",
     "a third column nobody writes or reads: proxy_numpy and yield_numpy use columns 0 and 1"),
    *(("slave_sim/clay/sim.py", before, after, _CUDA) for before, after in (
        ('runtime["pinned"] = {name: wp.zeros((lanes, columns.get(name, 2)),',
         'runtime["pinned"] = {name: wp.zeros((lanes, columns.get(name, 3)),'),
        ('dtype=wp.float64, device="cpu", pinned=True)',
         'dtype=wp.float64, device="cpu", pinned=False)'),
        ("for name in self._INPUTS + self._OUTPUTS}", "for name in self._INPUTS - self._OUTPUTS}"),
        ("for name in self._INPUTS:", "for name in []:"),
        ('for launch in runtime["launches"]:', "for launch in []:"),
        ("for name in self._OUTPUTS:", "for name in []:"))),
    ("slave_sim/clay/sim.py",
     "with wp.ScopedCapture(device=self.device, force_module_load=False) as capture:",
     "with wp.ScopedCapture(device=self.device, force_module_load=True) as capture:",
     "CUDA-only, and the same graph either way: True only loads every Warp module on the "
     "device before the capture (the step's kernels are loaded when their launches are "
     "recorded)"),
    ("master/hardware/can_driver.py", "self._sync_sent_s = 0.0", "self._sync_sent_s = 1.0",
     "read only by read() after sync() has set it"),
    *(("master/hardware/can_driver.py",
       "self._sync_sent_s = 0.0\nself._sync_drive_fault = [False, False]", after,
       "the first read() is configure's, inactive, where a drive fault commands nothing; it "
       "clears the flags for the next cycle") for after in (
        "self._sync_drive_fault = [True, False]", "self._sync_drive_fault = [False, True]")),
    *(("master/hardware/can_driver.py", "self._warnings = [0, 0]", after,
       "bit 0 is no watched warning bit: the first statusword differs from it, and its events "
       "are those of the watched bits that are on, as from 0")
      for after in ("self._warnings = [ 1, 0]", "self._warnings = [0, 1]")),
    ("master/hardware/can_driver.py", "self._expect_heartbeats(0.0)",
     "self._expect_heartbeats( 1.0)",
     "configure calls it again, with the time, before anything reads the heartbeat times"),
    ("master/hardware/can_driver.py", "self._dispatch[self.codec.frame_id] = (_SENSOR, 0)",
     "self._dispatch[self.codec.frame_id] = (_SENSOR, 1)",
     "the sensor frame's axis is never read: one frame carries both axes"),
    ("master/hardware/can_driver.py", "self.sync_counter_overflow = 0",
     "self.sync_counter_overflow = 1",
     "_plans() sets it at configure, before the first SYNC"),
    ("master/hardware/can_driver.py", "for count in range(1, 241)]",
     "for count in range(1, 242)]",
     "the overflow is at most 240 (0x1019's range, and the configuration's limit): the 241st "
     "counted SYNC is never sent"),
    ("master/hardware/can_driver.py", "file=sys.stderr, flush=True)",
     "file=sys.stderr, flush=False)",
     "stderr is line-buffered (Python 3.9 and later) and the line ends with a newline"),
    ("master/hardware/can_driver.py", "strict=True)):", "strict=False)):",
     "node_ids and eds_files are both pairs (CanSettings)"),
    ("master/hardware/can_driver.py",
     "for node, (dictionary, what) in zip(settings.node_ids, dictionaries, strict=True):",
     "for node, (dictionary, what) in zip(settings.node_ids, dictionaries, strict=False):",
     "dictionaries has one entry per node id (built from the same pairs just above)"),
    ("master/hardware/can_driver.py", "strict=True))", "strict=False))",
     "AXES and the drive states are both pairs"),
    ("master/hardware/can_driver.py",
     "self._stop_reported[axis] = True\ndrive_fault[axis] = True", "drive_fault[axis] = False",
     "only after the master's own stop, which tripped the driver: quick_stop() for a drive "
     "fault does nothing then"),
    ("master/hardware/can_driver.py",
     "if thread is not None and thread is not threading.current_thread():",
     "if thread is not None or thread is not threading.current_thread():",
     "python-can's ThreadBasedCyclicSendTask starts itself at construction: its thread is "
     "never None here"),
    ("master/hardware/can_driver.py", "thread.join(timeout=self._heartbeat_period_s + 0.5)",
     "thread.join(timeout=self._heartbeat_period_s + 1.5)",
     "a bound on the wait only: the stopped task's thread ends within one period"),
    *(("master/hardware/can_driver.py", before, after,
       "the two times are equal only when both are the same float reading of the monotonic "
       "clock (ns): the next reading decides the same way")
      for before, after in (
          ("if now >= self._heartbeat_due_s:", "if now > self._heartbeat_due_s:"),
          ("if clock >= deadline:", "if clock > deadline:"),
          ("if now - self._heartbeat_seen_s[axis] > self._heartbeat_timeout_s and (",
           "if now - self._heartbeat_seen_s[axis] >= self._heartbeat_timeout_s and ("),
          ("while (remaining := deadline - time.monotonic()) > 0.0:",
           "while (remaining := deadline - time.monotonic()) >= 0.0:"),
          ("if now >= deadline:", "if now > deadline:"),
          ("if now >= resend_at:", "if now > resend_at:"))),
    *(("master/hardware/can_driver.py", "self._pending_faults, [False, False])", after,
       "a list nothing reads after the call: during an SDO exchange an EMCY is logged and kept "
       "for the next reading, where the faults it gives act") for after in (
        "self._pending_faults, [True, False])", "self._pending_faults, [False, True])")),
    ("master/hardware/can_driver.py", "_OTHER = (0, 0)", "_OTHER = (0, 1)",
     "the axis of a frame of kind 0 (an id the driver does not know) is never read"),
    ("master/hardware/can_driver.py", "self._outer = False", "self._outer = True",
     "a burst's __enter__ sets it before its __exit__ reads it"),
    ("master/hardware/can_driver.py", "if now >= deadline:\nbreak", "continue",
     "past the deadline the loop's own condition is false too: continue leaves it as break "
     "does, to the same error"),
    ("slave_sim/clay/clay_kernels.py", "u = wp.clamp(t, wp.float64(0.0), wp.float64(1.0))",
     "u = wp.clamp(t, wp.float64(0.0), wp.float64( 2.0))",
     "the cut only reaches cells with distance < outer_radius = inner_radius + edge_width, "
     "where t = (distance - inner_radius) / edge_width < 1 (or an ulp above, where the "
     "smoothstep is 1 to double precision either way): the upper clamp never acts"),
)
#: pytest plugins a mutant run does without (unraisableexception's gc.collect() alone costs
#: 0.8 s per run over the preloaded libraries).
PYTEST_PLUGINS_OFF = ("-p", "no:cacheprovider", "-p", "no:unraisableexception", "-p",
                      "no:threadexception", "-p", "no:benchmark", "-p", "no:junitxml", "-p",
                      "no:pastebin", "-p", "no:doctest")


@dataclass
class Mutant:
    """One mutation of one module."""

    path: str
    operator: str
    occurrence: int
    line: int
    source: str
    before: str = ""  # the mutated line, stripped, before and after
    after: str = ""
    above: str = ""  # the non-blank line above it, stripped

    def diff(self, original: str) -> str:
        lines = difflib.unified_diff(original.splitlines(True), self.source.splitlines(True),
                                     f"a/{self.path}", f"b/{self.path}", n=0)
        return "".join(lines)


@dataclass
class ModuleResult:
    """The outcome for one module."""

    killed: int = 0
    survived: int = 0
    timed_out: int = 0
    equivalent: int = 0  # listed in EQUIVALENT, not run, not counted
    generated: int = 0  # all mutants of the module, before sampling
    seconds: float = 0.0
    survivors: list[Mutant] = field(default_factory=list)

    @property
    def score(self) -> float:
        total = self.killed + self.survived
        return self.killed / total if total else 1.0

    def as_dict(self) -> dict[str, float | int]:
        return {"killed": self.killed, "survived": self.survived, "score": round(self.score, 4),
                "timed_out": self.timed_out, "equivalent": self.equivalent,
                "generated": self.generated, "seconds": round(self.seconds, 1)}


def module_name(path: str) -> str:
    """``master/node.py`` -> ``haptic.master.node``, by the package-dir mapping of
    pyproject.toml."""
    with open(ROOT / "pyproject.toml", "rb") as handle:
        package_dir = tomllib.load(handle)["tool"]["setuptools"]["package-dir"]
    folder, _, stem = path.rpartition("/")
    for package, directory in package_dir.items():
        if folder == directory or folder.startswith(directory + "/"):
            rest = folder[len(directory):].strip("/").replace("/", ".")
            return ".".join(part for part in (package, rest, stem.removesuffix(".py")) if part)
    raise SystemExit(f"mutation_score: {path} is in no package of pyproject.toml")


def _keep(operator: str, index_at_node: int) -> bool:
    """One mutant per site: NumberReplacer offers +1 and -1, keep +1."""
    return not (operator == "core/NumberReplacer" and index_at_node > 0)


def _annotation_spans(source: str) -> list[tuple[tuple[int, int], tuple[int, int]]]:
    """(start, end) positions (line, column) of every type annotation: with ``from __future__
    import annotations`` they are never evaluated, so their mutants (``X | None`` ->
    ``X & None``) are equivalent by construction and not made."""
    spans = []
    for node in ast.walk(ast.parse(source)):
        found = []
        if isinstance(node, ast.arg | ast.AnnAssign) and node.annotation is not None:
            found.append(node.annotation)
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and node.returns:
            found.append(node.returns)
        spans.extend(((a.lineno, a.col_offset), (a.end_lineno, a.end_col_offset))
                     for a in found)
    return spans


def mutants(path: str, keep_line: Callable[[str], bool] | None = None) -> list[Mutant]:
    """Every mutant of ``path`` (relative to the repository), in source order; with
    ``keep_line``, only those of the lines (stripped) it keeps: the same mutants, without
    making the others (each is a whole re-parse of the file)."""
    from cosmic_ray.ast import ast_nodes, get_ast
    from cosmic_ray.mutating import MutationVisitor
    from cosmic_ray.plugins import get_operator

    source = (ROOT / path).read_text()
    lines = source.splitlines()
    annotations = _annotation_spans(source)
    found = []
    for name in OPERATORS:
        operator = get_operator(name)()
        occurrence = 0
        for node in ast_nodes(get_ast(source)):
            for index, (start, _end) in enumerate(operator.mutation_positions(node)):
                line = start[0]
                if (_keep(name, index) and not lines[line - 1].rstrip().endswith(PRAGMA)
                        and (keep_line is None or keep_line(lines[line - 1].strip()))
                        and not any(a <= start < b for a, b in annotations)):
                    try:
                        mutated = MutationVisitor.mutate_code(source, operator, occurrence)
                    except AttributeError:
                        # cosmic-ray's ExceptionReplacer cannot replace a dotted name in an
                        # except clause (``except (can.CanError, OSError)``): not made
                        mutated = None
                    if mutated is not None and mutated != source:
                        after = mutated.splitlines()[line - 1].strip()
                        above = next((text.strip() for text in reversed(lines[:line - 1])
                                      if text.strip()), "")
                        found.append(Mutant(path, name, occurrence, line, mutated,
                                            lines[line - 1].strip(), after, above))
                occurrence += 1
    found.sort(key=lambda m: (m.line, m.operator, m.occurrence))
    return found


def _serve_mutant(name: str, path: Path, source: str) -> None:
    """In the child: import ``name`` from ``source`` instead of the file (and let linecache,
    which inspect and Warp read kernel source through, return it too)."""
    import importlib.abc
    import importlib.util
    import linecache

    filename = str(path)
    linecache.cache[filename] = (len(source), None, source.splitlines(True), filename)

    class Loader(importlib.abc.Loader):
        def create_module(self, spec):  # noqa: ANN001, ANN202
            return None

        def exec_module(self, module):  # noqa: ANN001, ANN202
            module.__file__ = filename
            exec(compile(source, filename, "exec", dont_inherit=True), module.__dict__)

        def get_source(self, fullname):  # noqa: ANN001, ANN202
            return source

    class Finder(importlib.abc.MetaPathFinder):
        def find_spec(self, fullname, target_path=None, target=None):  # noqa: ANN001, ANN202
            if fullname != name:
                return None
            return importlib.util.spec_from_loader(name, Loader(), origin=filename)

    sys.meta_path.insert(0, Finder())


def _child(tests: tuple[str, ...], timeout_s: float, mutant: Mutant | None,
           verbose: bool) -> None:
    """In a forked child: run ``tests`` (on ``mutant``) and exit 0 when they pass."""
    status = 3
    try:
        os.chdir(ROOT)
        if not verbose:
            null = os.open(os.devnull, os.O_WRONLY)
            os.dup2(null, 1)
            os.dup2(null, 2)
        signal.signal(signal.SIGALRM, signal.SIG_DFL)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        signal.signal(signal.SIGINT, signal.SIG_DFL)
        signal.alarm(max(1, int(timeout_s)))
        if mutant is not None:
            _serve_mutant(module_name(mutant.path), ROOT / mutant.path, mutant.source)
        from hypothesis import HealthCheck
        from hypothesis import settings as hypothesis_settings

        # The same examples for every mutant and the baseline, no shared example database,
        # and no health check that a loaded machine fails (that would count as a kill).
        hypothesis_settings.register_profile(
            "mutation", derandomize=True, database=None, deadline=None,
            suppress_health_check=list(HealthCheck))
        hypothesis_settings.load_profile("mutation")
        import pytest

        code = pytest.main(["-x", "-q", "--no-header", *PYTEST_PLUGINS_OFF,
                            *(str(ROOT / t) for t in tests)])
        status = 0 if code == 0 else 1
    finally:
        sys.stdout.flush()
        os._exit(status)


def _outcome(status: int) -> str:
    if os.WIFSIGNALED(status):
        return "timeout" if os.WTERMSIG(status) == signal.SIGALRM else "failed"
    return "passed" if os.WEXITSTATUS(status) == 0 else "failed"


#: Children running now (pid -> mutant), ended by the parent if it is stopped.
_RUNNING: dict[int, Mutant | None] = {}


def run_tests(tests: tuple[str, ...], timeout_s: float, mutant: Mutant | None = None,
              verbose: bool = False) -> str:
    """Run ``tests`` in a forked child (on ``mutant`` if given): ``passed``, ``failed`` or
    ``timeout``."""
    pid = os.fork()
    if pid == 0:
        _child(tests, timeout_s, mutant, verbose)
    _RUNNING[pid] = mutant
    _, status = os.waitpid(pid, 0)
    del _RUNNING[pid]
    return _outcome(status)


def run_mutants(tests: tuple[str, ...], timeout_s: float, found: list[Mutant], jobs: int):
    """Yield (mutant, outcome) for each of ``found``, ``jobs`` children at a time."""
    pending = list(reversed(found))
    while pending or _RUNNING:
        while pending and len(_RUNNING) < jobs:
            mutant = pending.pop()
            pid = os.fork()
            if pid == 0:
                _child(tests, timeout_s, mutant, False)
            _RUNNING[pid] = mutant
        pid, status = os.wait()
        mutant = _RUNNING.pop(pid, None)
        if mutant is not None:
            yield mutant, _outcome(status)


def _end_children() -> None:
    for pid in list(_RUNNING):
        try:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
        except (ProcessLookupError, ChildProcessError):
            pass
        _RUNNING.pop(pid, None)


def equivalent_reason(mutant: Mutant) -> str | None:
    """Why ``mutant`` is equivalent, if :data:`EQUIVALENT` lists it (a line that occurs more
    than once is told apart by the line above it: ``above\nline``)."""
    for path, before, after, why in EQUIVALENT:
        if (path, after) != (mutant.path, mutant.after):
            continue
        above, _, line = before.rpartition("\n")
        if line == mutant.before and (not above or above == mutant.above):
            return why
    return None


def score_module(path: str, progress: bool, jobs: int, everything: bool) -> ModuleResult:
    """Baseline (the tests must pass unmutated; its time sets the limit), then the mutants
    (every one, or the module's sample), less the listed equivalent ones."""
    target = MODULES[path]
    result = ModuleResult()
    start = time.monotonic()
    baseline = run_tests(target.tests, 600.0)
    baseline_s = time.monotonic() - start
    if baseline != "passed":
        raise SystemExit(f"mutation_score: the tests of {path} fail unmutated ({baseline}); "
                         f"run: pytest -x {' '.join(target.tests)}")
    # A mutated Warp kernel compiles first (about 2 s here); a mutant much slower than the
    # baseline is stuck (an endless loop, say) and counts as killed.
    timeout_s = 3.0 * baseline_s + 20.0
    found = mutants(path)
    result.generated = len(found)
    if not everything and target.every > 1:
        found = found[::target.every]
    runnable = []
    for mutant in found:
        if equivalent_reason(mutant) is None:
            runnable.append(mutant)
        else:
            result.equivalent += 1
    original = (ROOT / path).read_text()
    mark = {"passed": "SURVIVED", "failed": "killed", "timeout": "killed (timeout)"}
    for number, (mutant, outcome) in enumerate(run_mutants(target.tests, timeout_s, runnable,
                                                           jobs), 1):
        if outcome == "passed":
            result.survived += 1
            result.survivors.append(mutant)
        else:
            result.killed += 1
            result.timed_out += outcome == "timeout"
        if progress:
            print(f"  [{number}/{len(runnable)}] {path}:{mutant.line} {mutant.operator}: "
                  f"{mark[outcome]}", file=sys.stderr, flush=True)
            if outcome == "passed":
                print(mutant.diff(original), file=sys.stderr, flush=True)
    result.survivors.sort(key=lambda m: m.line)
    result.seconds = time.monotonic() - start
    return result


def _preload(cache_dir: str) -> None:
    import importlib

    for name in PRELOAD:
        try:
            importlib.import_module(name)
        except ImportError:
            pass
    import warp as wp

    wp.config.log_level = wp.LOG_WARNING
    wp.config.kernel_cache_dir = cache_dir
    wp.config.enable_backward = False  # no kernel here is differentiated: half the compile
    wp.init()
    import gc

    gc.collect()
    gc.freeze()  # the children's collections skip the preloaded heap
    loaded = [m for m in sys.modules if m == "haptic" or m.startswith("haptic.")]
    if loaded:  # a child must import every haptic module afresh (the mutant among them)
        raise SystemExit(f"mutation_score: preloading imported {loaded}")


def _stop(signum: int, _frame: object) -> None:
    raise KeyboardInterrupt(f"signal {signum}")


def equivalents_table() -> str:
    """The :data:`EQUIVALENT` list as a Markdown table (docs/testing.md)."""
    rows = ["| module | line | mutant | why it is equivalent |", "|---|---|---|---|"]
    def cell(text: str) -> str:
        return text.replace("|", "\\|")

    for path, before, after, why in EQUIVALENT:
        above, _, line = before.rpartition("\n")
        where = f"`{cell(line)}` (after `{cell(above)}`)" if above else f"`{cell(line)}`"
        rows.append(f"| `{path}` | {where} | `{cell(after)}` | {cell(why)} |")
    return "\n".join(rows)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.split("\n\n")[0])
    parser.add_argument("--module", action="append", metavar="PATH",
                        help=f"a module to mutate (repeatable; default all: {', '.join(MODULES)})")
    parser.add_argument("--json", action="store_true", help="print JSON on stdout")
    parser.add_argument("--all", action="store_true",
                        help="every mutant, also of the sampled modules (the kernel)")
    parser.add_argument("--jobs", type=int, default=1, metavar="N",
                        help="mutants tested at once (default 1; one per free core)")
    parser.add_argument("--survivors", action="store_true",
                        help="print each surviving mutant's diff (stderr)")
    parser.add_argument("--count", action="store_true",
                        help="only count the mutants per module, run nothing")
    parser.add_argument("--equivalents", action="store_true",
                        help="print the table of equivalent mutants (Markdown), run nothing")
    parser.add_argument("--progress", action="store_true", help="one line per mutant on stderr")
    args = parser.parse_args(argv)
    paths = args.module or list(MODULES)
    for path in paths:
        if path not in MODULES:
            parser.error(f"--module {path}: not configured (known: {', '.join(MODULES)})")
    if args.jobs < 1:
        parser.error("--jobs must be at least 1")
    if args.equivalents:
        print(equivalents_table())
        return 0
    if args.count:
        counts = {path: len(mutants(path)) for path in paths}
        print(json.dumps(counts) if args.json else "\n".join(f"{n:5d}  {p}"
                                                             for p, n in counts.items()))
        return 0
    start = time.monotonic()
    cache_dir = tempfile.mkdtemp(prefix="mutation-warp-cache-")
    signal.signal(signal.SIGTERM, _stop)
    try:
        _preload(cache_dir)
        results = {}
        for path in paths:
            results[path] = result = score_module(path, args.progress, args.jobs, args.all)
            print(f"mutation_score: {path}: {result.killed} killed, {result.survived} survived "
                  f"({result.score * 100:.1f} %), {result.equivalent} equivalent, "
                  f"{result.seconds:.0f} s", file=sys.stderr, flush=True)
    except KeyboardInterrupt:
        print("mutation_score: stopped", file=sys.stderr)
        return 130
    finally:
        _end_children()
        shutil.rmtree(cache_dir, ignore_errors=True)
    elapsed_s = time.monotonic() - start
    killed = sum(r.killed for r in results.values())
    total = killed + sum(r.survived for r in results.values())
    total_score = killed / total if total else 1.0
    if args.json:
        print(json.dumps({"modules": {p: r.as_dict() for p, r in results.items()},
                          "total_score": round(total_score, 4),
                          "seconds": round(elapsed_s, 1), "jobs": args.jobs,
                          "sampled": not args.all}, indent=2))
    else:
        print(f"{'module':26s} {'killed':>7s} {'survived':>9s} {'score':>7s} {'equiv.':>7s} "
              f"{'of':>5s} {'time':>6s}")
        for path, r in results.items():
            print(f"{path:26s} {r.killed:7d} {r.survived:9d} {r.score * 100:6.1f}% "
                  f"{r.equivalent:7d} {r.generated:5d} {r.seconds:5.0f}s")
        print(f"{'total':26s} {killed:7d} {total - killed:9d} {total_score * 100:6.1f}% "
              f"{'':13s} {elapsed_s:5.0f}s")
    if args.survivors:
        for path, r in results.items():
            original = (ROOT / path).read_text()
            for mutant in r.survivors:
                print(f"--- survivor {path}:{mutant.line} {mutant.operator}", file=sys.stderr)
                print(mutant.diff(original), file=sys.stderr)
    print(f"mutation_score: {len(paths)} module(s), {total} mutants tested in "
          f"{elapsed_s:.0f} s ({elapsed_s / 60:.1f} min, --jobs {args.jobs})", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
