"""The simulated rig's devices in their own process, and the ``sim`` backend that starts it.

A real rig's drives and force sensor are separate devices on the CAN bus; so is their
emulation. :func:`run_emulator` is the emulator process's serving loop (``haptic-rig-sim``,
:mod:`haptic.master.simulated_rig.cli`): the frame logic of
:class:`~haptic.master.simulated_rig.can_devices.SimulatedCanRig` on a python-can bus that crosses
processes,
blocking on the bus's receive (no spinning) and answering each SYNC with both TPDO1s and the
sensor frame. :class:`EmulatedRigHardware` (backend ``sim``) is the unchanged
:class:`~haptic.master.hardware.can_driver.CanHandleDriver` on that bus plus the emulator as a child
process, started by ``configure()`` on a bus private to the run and ended (by its own PID,
always reaped) by ``cleanup()``.

The bus (``[master.sim.emulator]``): ``unix_datagram`` (:mod:`haptic.master.hardware.unix_can`, a
temporary directory per run; the default) or python-can's ``udp_multicast`` (a free UDP port
per run). Both cross processes; the Unix datagrams cost less per frame, as they pass no
network device (docs/measurements/can_stack.md has the figures).

The simulated operator feels the tool force the master reflects: ``present_tool_force`` sends
it to the emulator as the operator display frame
(:data:`~haptic.master.simulated_rig.operator_frames.OPERATOR_DISPLAY_ID`, emulator-only) after the
cycle's RPDOs,
all of them in the next SYNC's datagram (one wake-up of the emulator a cycle); where the display
frame comes before its SYNC, the emulator prepares its answer while it waits
(``SimulatedCanRig.prepare_ahead``).

Where the master's loop has CPUs of its own (``[runner] loop_cpus``), the emulator runs on
them too (:attr:`EmulatedRigHardware.emulator_cpus`), under normal scheduling: it answers the
SYNC the master sends before its tick while the master's loop sleeps, on the same CPU, as a
rig's drives answer while the master waits. Left to run anywhere on a machine with few CPUs
it waits behind the slave's loop, and the master's read stage grows a long tail in
``haptic-session``; on the loop's CPU under SCHED_BATCH (which has no wake-up preemption) it
still does at times, under normal scheduling not (docs/programs.md;
docs/measurements/can_stack.md has the figures). Elsewhere it runs under SCHED_BATCH, so its
wake-ups never cut into a loop's tick.
"""

from __future__ import annotations

import collections
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from typing import IO, Any, TextIO

import can
import numpy as np

from haptic.common.config import to_toml
from haptic.common.config.runner_schema import MAX_FIFO_PRIORITY, parse_cpus
from haptic.common.runtime.machine import process_cpu_s
from haptic.master.hardware.can_driver import CanHandleDriver
from haptic.master.hardware.interface import (
    HandleHardware,
    HandleReading,
    HardwareError,
    LifecycleState,
)
from haptic.master.hardware.unix_can import INTERFACE as UNIX_INTERFACE
from haptic.master.settings import master_settings
from haptic.master.simulated_rig.can_devices import SimulatedCanRig
from haptic.master.simulated_rig.operator_frames import (
    OPERATOR_DISPLAY_ID,
    OPERATOR_READY_ID,
    encode_operator_display,
)

#: The emulator's first line on stdout once its bus is open and it answers frames.
READY_PREFIX = "haptic-rig-sim: ready"
#: python-can's udp_multicast port when none is given (what ``--rig can`` uses by default).
DEFAULT_UDP_PORT = 43113
#: The bus of ``haptic-rig-sim`` started by hand without a channel, per interface: the
#: unix_datagram directory, python-can's udp_multicast IPv4 group.
DEFAULT_CHANNELS = {
    UNIX_INTERFACE: os.path.join(tempfile.gettempdir(), "haptic-rig-sim"),
    "udp_multicast": "239.74.163.2",
}
#: How often the serving loop looks at the stop request, the duration and its parent, s.
POLL_S = 0.1
#: How long cleanup() waits for the emulator to end after SIGTERM before SIGKILL, s.
STOP_TIMEOUT_S = 5.0
#: Lines of the emulator's output kept for error messages.
OUTPUT_TAIL_LINES = 20
#: Errors printed by the emulator before it only counts them.
MAX_PRINTED_ERRORS = 10


def free_udp_port() -> int:
    """A UDP port no socket on this host is bound to now (the kernel's pick), for a run's
    private udp_multicast bus."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("", 0))
        return int(probe.getsockname()[1])


# --- the emulator process ---------------------------------------------------------------


def run_emulator(rig: SimulatedCanRig, bus_options: dict[str, Any],
                 should_stop: Callable[[], bool], out: TextIO = sys.stdout,
                 err: TextIO = sys.stderr) -> int:
    """Serve the devices ``rig`` on the bus ``can.Bus(**bus_options)`` until ``should_stop()``
    is true; returns the exit status (0, or 1 when the bus cannot open).

    Prints :data:`READY_PREFIX` and the bus on one line of ``out`` once it answers frames,
    and one line when it stops. The loop blocks on the bus's receive (at most
    :data:`POLL_S` at a time, to look at ``should_stop``): no spinning.
    """
    try:
        bus = can.Bus(**bus_options)
    except (can.CanError, OSError, ValueError, ImportError) as error:
        options = ", ".join(f"{k}={v}" for k, v in bus_options.items())
        print(f"haptic-rig-sim: cannot open the CAN bus ({options}): {error}", file=err)
        return 1
    errors = 0

    def report(text: str) -> None:
        nonlocal errors
        errors += 1
        if errors <= MAX_PRINTED_ERRORS:
            print(f"haptic-rig-sim: frame error: {text}", file=err, flush=True)

    try:
        rig.attach(bus)
        settings = rig.settings
        where = " ".join(f"{k} {v}" for k, v in bus_options.items() if k != "interface")
        operator = rig.model.operator
        spec = ",".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}"
                        for k, v in operator.params.items())
        print(f"{READY_PREFIX} on {bus_options.get('interface')} {where} (pid {os.getpid()}): "
              f"x drive node {settings.x_node_id}, y drive node {settings.y_node_id}, sensor "
              f"0x{rig.codec.frame_id:03X}, operator {operator.kind}:{spec}",
              file=out, flush=True)
        rig.serve(should_stop, POLL_S, report)
    finally:
        bus.shutdown()
    # unix_datagram only: frames a member's full queue made wait, or never took
    queue = (f", {bus.full_queue_waits} sends waited for a full queue, "
             f"{bus.dropped_datagrams} datagrams dropped"
             if hasattr(bus, "dropped_datagrams") else "")
    print(f"haptic-rig-sim: stopped after {rig.sync_count} SYNCs ({rig.prepared_syncs} "
          f"answered as prepared), {errors} frame errors{queue}", file=out, flush=True)
    return 0


def use_batch_scheduling() -> str | None:
    """Put this process under SCHED_BATCH (Linux; no privilege needed): its wake-ups never
    preempt a running task, so a frame that wakes the emulator while the master's loop runs
    (the operator display frame, whose answer it then prepares) waits for that CPU to be free
    instead of cutting into the loop's tick. Returns a warning when refused, else ``None``."""
    return _use_policy("SCHED_BATCH", 0)


def use_fifo_scheduling(priority: int) -> str | None:
    """Put this thread (the emulator's serving loop; threads it starts later inherit it)
    under SCHED_FIFO at ``priority`` (1-99; needs the privilege to). Where the master's loop
    runs in SCHED_FIFO on the same CPU, the drives are above it: they answer as soon as the
    SYNC comes, and a kernel thread of normal scheduling that holds the CPU for a long time
    (DAMON's ``kdamond``, for instance) gives it up at its next preemption point
    instead of at its end. Returns a warning when refused, else ``None`` (the emulator then
    runs under normal scheduling)."""
    return _use_policy("SCHED_FIFO", priority)


def _use_policy(name: str, priority: int) -> str | None:
    """The calling thread under the policy ``os.<name>`` at ``priority``; the warning of a
    refusal (or of a platform without it), else ``None``."""
    policy = getattr(os, name, None)
    if policy is None:
        return f"{name} is not available here: normal scheduling"
    try:
        os.sched_setscheduler(0, policy, os.sched_param(priority))
    except OSError as error:
        label = f"{name} {priority}" if priority else name
        return f"{label} refused ({error}): normal scheduling"
    return None


class StopRequest:
    """``should_stop`` of the emulator's loop: SIGINT/SIGTERM, the end of ``duration_s``
    (``None``: none) or the end of the parent process ``parent_pid`` (``None``: not
    watched; the emulator of a master that was killed ends by itself)."""

    def __init__(self, duration_s: float | None = None, parent_pid: int | None = None) -> None:
        self.duration_s = duration_s
        self.parent_pid = parent_pid
        self.signalled: int | None = None
        self._start = time.monotonic()

    def install(self) -> None:
        """Handle SIGINT and SIGTERM (main thread only): stop the loop, exit status 0."""
        for number in (signal.SIGINT, signal.SIGTERM):
            signal.signal(number, self._on_signal)

    def _on_signal(self, number: int, frame: object) -> None:
        del frame
        self.signalled = number

    def __call__(self) -> bool:
        if self.signalled is not None:
            return True
        if self.parent_pid is not None and os.getppid() != self.parent_pid:
            return True
        return self.duration_s is not None and (
            time.monotonic() - self._start >= self.duration_s)


# --- the sim backend ----------------------------------------------------------------------


class _ChildOutput:
    """Reads a child's output on a thread until EOF (so the child never blocks on a full
    pipe), keeps the last lines, and says when the ready line came."""

    def __init__(self, stream: IO[str]) -> None:
        self.stream = stream
        self.lines: collections.deque[str] = collections.deque(maxlen=OUTPUT_TAIL_LINES)
        self.ready = False
        self.settled = threading.Event()  # the ready line or EOF
        self._thread = threading.Thread(target=self._drain, name="rig-sim-output", daemon=True)
        self._thread.start()

    def _drain(self) -> None:
        try:
            for line in self.stream:
                line = line.rstrip("\n")
                self.lines.append(line)
                if not self.ready and line.startswith(READY_PREFIX):
                    self.ready = True
                    self.settled.set()
        except (OSError, ValueError):
            pass  # the pipe was closed under us: nothing more to read
        finally:
            self.settled.set()

    def tail(self) -> str:
        """The last lines, joined with " | " (one line for an error message)."""
        return " | ".join(self.lines) or "no output"

    def close(self, timeout_s: float) -> None:
        """Wait for EOF (the child has ended), then close the pipe."""
        self._thread.join(timeout=timeout_s)
        if not self._thread.is_alive():
            self.stream.close()


class EmulatedRigHardware(HandleHardware):
    """Backend ``sim``: the CAN driver against the rig's devices emulated in a child process
    (``haptic-rig-sim``) on a bus that crosses processes.

    ``configure()`` starts the emulator with this run's whole configuration (a temporary
    TOML file, removed once it is read) on a bus private to the run, waits at most
    ``start_timeout_s`` for its ready line, then configures the driver; ``cleanup()`` (also
    run when configure fails) ends the emulator by its PID (SIGTERM, SIGKILL after
    :data:`STOP_TIMEOUT_S`), reaps it and removes the run's bus directory. The emulator runs
    in its own process group (a terminal's Ctrl-C goes to the master, which ends it) and ends by
    itself when the master is gone. Its output is read on a thread, so it never blocks;
    :attr:`process` stays set after the cleanup, reaped. ``present_tool_force`` sends the
    operator display frame.
    """

    def __init__(self, config: dict[str, Any]) -> None:
        self.config = config
        self.settings = master_settings(config)
        self.emulator = self.settings.sim.emulator
        self.driver: CanHandleDriver | None = None
        self.process: subprocess.Popen[str] | None = None
        #: The run's ``can.Bus`` options (its private channel or port), set by configure().
        self.bus_options: dict[str, Any] = {}
        self._private_directory: str | None = None
        self._output: _ChildOutput | None = None  # kept after the stop, for its last lines
        self._display: bytes | None = None
        #: the CPUs the emulator was placed on (the master's loop CPUs; None: anywhere) and
        #: why it could not be, if it could not
        self.emulator_cpus: tuple[int, ...] | None = None
        self.emulator_cpu_warning: str | None = None

    @property
    def lifecycle_state(self) -> LifecycleState:
        if self.driver is None:
            return LifecycleState.UNCONFIGURED
        return self.driver.lifecycle_state

    def configure(self) -> None:
        if self.lifecycle_state is not LifecycleState.UNCONFIGURED:
            return
        try:
            self.bus_options = self._private_bus()
            self._start_emulator(self.bus_options)
            self.driver = CanHandleDriver(self.settings.can, self.bus_options,
                                          self.settings.sim.pdo_timeout_s,
                                          self.config["model"]["sample_period_s"])
            self.driver.configure()
        except BaseException:
            self.driver = None
            self._stop_emulator()
            raise

    def summary(self) -> dict[str, Any]:
        return self.driver.summary() if self.driver is not None else {}

    def device_process_cpu_s(self) -> float | None:
        """The emulator process's CPU time so far, s (None when it is not running)."""
        process = self.process
        if process is None or process.poll() is not None:
            return None
        return process_cpu_s(process.pid)

    def _private_bus(self) -> dict[str, Any]:
        """This run's bus: a fresh directory (unix_datagram, channel "") or a free UDP port
        (udp_multicast, port 0), unless the configuration names one."""
        emulator = self.emulator
        channel, port = emulator.channel, emulator.port
        if emulator.interface == UNIX_INTERFACE and not channel:
            self._private_directory = tempfile.mkdtemp(prefix="haptic-rig-sim-")
            channel = self._private_directory
        if emulator.interface == "udp_multicast" and port == 0:
            port = free_udp_port()
        return emulator.bus_options(channel, port)

    def _start_emulator(self, bus_options: dict[str, Any]) -> None:
        with tempfile.NamedTemporaryFile("w", prefix="haptic-rig-sim-", suffix=".toml",
                                         delete=False) as file:
            file.write(to_toml(self.config))
            config_path = file.name
        try:
            loop_cpus = parse_cpus(str(self.config["runner"]["loop_cpus"]))
            command = [sys.executable, "-m", "haptic.master.simulated_rig.cli", "--config",
                       config_path, "--can-interface", bus_options["interface"],
                       "--can-channel", bus_options["channel"], "--parent-pid", str(os.getpid()),
                       "--operator-waits-for-lamp", *emulator_scheduling(self.config["runner"])]
            if "port" in bus_options:
                command += ["--can-port", str(bus_options["port"])]
            try:
                # Its own process group: a terminal's Ctrl-C reaches the master, which ends
                # it. Not its own session: with the kernel's autogroup (one scheduling group
                # per session), a group of one mostly sleeping process is left unscheduled for
                # long stretches beside CPU hogs, SYNCs waiting in its queue; in the session's
                # group it answers in time (docs/measurements/can_stack.md).
                self.process = subprocess.Popen(
                    command, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                    stderr=subprocess.STDOUT, text=True, errors="replace",
                    process_group=0)
            except OSError as error:
                raise HardwareError(f"cannot start haptic-rig-sim: {error}") from None
            self._place_emulator(self.process.pid, loop_cpus)
            assert self.process.stdout is not None
            self._output = _ChildOutput(self.process.stdout)
            timeout_s = self.emulator.start_timeout_s
            self._output.settled.wait(timeout_s)
            if not self._output.ready:
                if self._output.settled.is_set():  # EOF: it ended
                    status = self.process.wait(timeout=STOP_TIMEOUT_S)
                    raise HardwareError(f"haptic-rig-sim ended (exit status {status}) before "
                                        f"it was ready: {self._output.tail()}")
                raise HardwareError(f"haptic-rig-sim not ready within {timeout_s:g} s "
                                    f"([master.sim.emulator] start_timeout_s): "
                                    f"{self._output.tail()}")
        finally:
            os.unlink(config_path)  # read before the ready line, or no longer needed

    def _place_emulator(self, pid: int, cpus: tuple[int, ...]) -> None:
        """Put the emulator on the master's loop CPUs (``cpus``, ``[runner] loop_cpus``),
        before it starts its threads (they inherit it); nothing where those are not set. A
        refusal is kept in :attr:`emulator_cpu_warning`, never an error: the emulator then
        runs anywhere."""
        self.emulator_cpus = None
        self.emulator_cpu_warning = None
        if not cpus:
            return
        if not hasattr(os, "sched_setaffinity"):
            self.emulator_cpu_warning = ("CPU affinity is a Linux setting: the emulator runs "
                                         "anywhere")
            return
        try:
            os.sched_setaffinity(pid, cpus)
        except OSError as error:
            self.emulator_cpu_warning = (f"the emulator's CPUs {','.join(map(str, cpus))} were "
                                         f"refused ({error}): it runs anywhere")
            return
        self.emulator_cpus = tuple(sorted(cpus))

    def _stop_emulator(self) -> None:
        process = self.process
        if process is not None and process.returncode is None:
            if process.poll() is None:
                process.send_signal(signal.SIGTERM)  # by its own PID
                try:
                    process.wait(timeout=STOP_TIMEOUT_S)
                except subprocess.TimeoutExpired:
                    process.kill()
                    process.wait()
        if self._output is not None:
            self._output.close(STOP_TIMEOUT_S)
        if self._private_directory is not None:
            shutil.rmtree(self._private_directory, ignore_errors=True)
            self._private_directory = None

    @property
    def emulator_output(self) -> str:
        """The emulator's last lines of output (one line), for diagnostics."""
        return self._output.tail() if self._output is not None else ""

    def activate(self) -> None:
        if self.driver is None:
            raise HardwareError("activate needs the inactive state (now unconfigured)")
        self.driver.activate()

    def deactivate(self) -> None:
        if self.driver is not None:
            self.driver.deactivate()

    def cleanup(self) -> None:
        try:
            if self.driver is not None:
                self.driver.cleanup()
        finally:
            self.driver = None
            self._display = None
            self._stop_emulator()

    def sync(self) -> None:
        if self.driver is None:
            raise HardwareError("sync needs a configured driver")
        self._send_display()
        self.driver.sync()

    def read(self) -> HandleReading:
        if self.driver is None:
            raise HardwareError("read needs a configured driver")
        self._send_display()
        return self.driver.read()

    def write(self, position_command_m: np.ndarray) -> None:
        if self.driver is None:
            return
        # the RPDOs and the display frame go out with the next SYNC, in one datagram: one
        # wake-up of the emulator a cycle, and none in the loop's tick
        with self.driver.until_sync():
            self.driver.write(position_command_m)
            self._send_display()

    def stop_motion(self, reason: str) -> None:
        if self.driver is not None:
            self.driver.stop_motion(reason)

    def resume_motion(self) -> None:
        if self.driver is not None:
            self.driver.resume_motion()

    def present_tool_force(self, tool_force_N: np.ndarray) -> None:
        """Send the tool force (N) to the emulated operator: the operator display frame goes
        out after this cycle's RPDOs (or before the next SYNC, whichever comes first)."""
        self._display = encode_operator_display(tool_force_N)

    def present_forces_enabled(self, enabled: bool) -> None:
        """The master's ready lamp to the emulated operator (sent at once; transitions only)."""
        if self.driver is None or self.driver.lifecycle_state is LifecycleState.UNCONFIGURED:
            return
        self.driver.send_frame(OPERATOR_READY_ID, b"\x01" if enabled else b"\x00",
                               extended=True)

    def _send_display(self) -> None:
        if self._display is None or self.driver is None:
            return
        if self.driver.lifecycle_state is LifecycleState.UNCONFIGURED:
            return
        payload, self._display = self._display, None
        self.driver.send_frame(OPERATOR_DISPLAY_ID, payload, extended=True)


def emulator_scheduling(runner: dict[str, Any]) -> list[str]:
    """``haptic-rig-sim``'s scheduling options for the master's ``[runner]`` table: on the
    loop's CPUs (``loop_cpus``) SCHED_FIFO one above a SCHED_FIFO loop
    (``realtime_priority``), normal scheduling beside a loop of normal scheduling; elsewhere
    SCHED_BATCH."""
    if not parse_cpus(str(runner["loop_cpus"])):
        return ["--scheduling", "batch"]
    priority = int(runner["realtime_priority"])
    if 0 < priority < MAX_FIFO_PRIORITY:
        return ["--scheduling", "fifo", "--rt-priority", str(priority + 1)]
    return ["--scheduling", "normal"]


def emulated_rig_hardware(config: dict[str, Any]) -> EmulatedRigHardware:
    """Backend ``sim`` for a validated configuration: ``[model]``, ``[master.can]`` (node ids,
    conversions, DBC), ``[master.sim]`` (operator, noise, seed, start, ``pdo_timeout_s``) and
    ``[master.sim.emulator]`` (the bus and the start timeout)."""
    return EmulatedRigHardware(config)
