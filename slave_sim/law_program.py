"""The networked slave in a lane-law mode (``[control] mode`` = ``wave``, ``four-channel``,
``four-channel-tdpa`` or ``mmt``): the virtual tool and the scenario's environment (the Warp
clay, or the linear one) driven by the law's slave side (common/control/law_pairs.py, the
Warp kernel the comparison's lanes step) over the law's link (common/wire/law_link.py), on
the real-time runner through the one tick driver.

One tick at Ts::

    poll       LawPeer.poll()              the newest handle message, the watchdog
    law        environment, then ControlPair.slave(...): the force the tool applies to the
               environment along its last move, the tool's command; this side's message
    move       the tool one period under its servo (common/control/law_pairs.py ``Device``:
               the comparison's tool device at the scenario's start), held in the work area
    send       LawPeer.send(enabled)
    telemetry  trace (the paper mode's columns: the cut's figures are taken alike)

The tool starts at the scenario's start position and its coordinates are the handle's (the
laws scale no positions). In the safe state (the watchdog not ``ok``) the law is not stepped
and the tool's servo holds where it was when forces went off, against the environment's
force. The tool stays inside the work area both sides hold (common/model/work_area.py): at
its wall the position is held and the outward velocity dropped. One law step per tick, on
this side's clock (the paper mode's pacing to the master's samples is that scheme's).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

from haptic.common.control.law_pairs import (
    TOOL_DEVICE_DAMPING_N_S_PER_M,
    TOOL_DEVICE_MASS_KG,
    ControlPair,
    Device,
    passivity_port,
)
from haptic.common.control.law_settings import LawSettings
from haptic.common.model.passivity import passivity_summary
from haptic.common.records.cutting import cutting_figures, steady_cut_fields
from haptic.common.records.trace import TraceRecorder
from haptic.common.runtime.law_peer import LawPeer, meet_law_peer
from haptic.common.runtime.program_harness import ProgramHarness
from haptic.common.runtime.runner import RunStats, StopSignals
from haptic.common.runtime.tick_driver import Stage, TickDriver
from haptic.common.wire.law_link import LawLink
from haptic.slave_sim.program_stages import SLAVE_TRACE_COLUMNS
from haptic.slave_sim.tool_path import ToolPath

#: The stages of one tick in a law mode, in order (the summary's ``stages``).
LAW_SLAVE_TICK_STAGES = ("poll", "law", "move", "send", "telemetry")
_NAN2 = (math.nan, math.nan)


class LawSlaveWorld:
    """The tool and its environment, one lane: the environment's force along the tool's
    move (:meth:`sense`) and the tool's step under a command (:meth:`move`), inside the work
    area's tool box ``(low, high)`` (m)."""

    def __init__(self, environment: Any, start_m: np.ndarray, period_s: float,
                 tool_box_m: tuple[np.ndarray, np.ndarray]) -> None:
        self.environment = environment
        self.state = environment.initial_state(1)
        self.tool = Device.at_rest(TOOL_DEVICE_MASS_KG, TOOL_DEVICE_DAMPING_N_S_PER_M, 1,
                                   start_m, period_s)
        self.previous_m = self.tool.position_m.copy()
        self.low_m, self.high_m = (np.asarray(bound, float) for bound in tool_box_m)
        self.fe = np.zeros((1, 2))
        self.cutting = False
        self.engagement = 0.0
        self.removed_volume_m3 = 0.0

    def sense(self) -> np.ndarray:
        """The force the tool applies to its environment, (1, 2), N, along its move since
        the last call (a non-finite force counts as 0 N)."""
        tool = self.tool
        result = self.environment.step(self.state, self.previous_m, tool.position_m,
                                       tool.velocity_m_per_s, np.zeros((1, 2)))
        self.previous_m = tool.position_m.copy()
        force = np.asarray(result.force_N, float).reshape(1, 2)
        self.fe = np.where(np.isfinite(force), force, 0.0)
        self.cutting = bool(np.asarray(result.cutting).reshape(-1)[0])
        self.engagement = float(np.asarray(result.engagement).reshape(-1)[0])
        self.removed_volume_m3 += float(np.asarray(result.removed_volume_m3).reshape(-1)[0])
        return self.fe

    def move(self, command_m: np.ndarray | None, command_m_per_s: np.ndarray) -> None:
        """One period of the tool towards the command under the environment's force, then
        held inside the work area (the outward velocity dropped at its wall)."""
        tool = self.tool
        tool.step(command_m, command_m_per_s, -self.fe)
        inside = np.clip(tool.position_m, self.low_m, self.high_m)
        at_wall = inside != tool.position_m
        tool.position_m[...] = inside
        tool.velocity_m_per_s[...] = np.where(at_wall, 0.0, tool.velocity_m_per_s)


class LawSlaveStages:
    """The slave's side of the tick driver in a law mode (see the module)."""

    stage_names = LAW_SLAVE_TICK_STAGES
    schedule_shift_ns = 0

    def __init__(self, control: str, peer: LawPeer, pair: ControlPair, world: LawSlaveWorld,
                 harness: ProgramHarness, trace: TraceRecorder) -> None:
        self.control, self.peer, self.pair, self.world = control, peer, pair, world
        self.harness, self.trace = harness, trace
        self.events: list[dict[str, Any]] = []
        self.tool_path = ToolPath()
        self.enabled = False
        self.hold_m = world.tool.position_m.copy()
        self.command: tuple[np.ndarray | None, np.ndarray] = (self.hold_m, np.zeros((1, 2)))
        self.now_s = 0.0
        self.max_force_N = 0.0

    def stages(self) -> tuple[Stage, ...]:
        return (self.poll, self.law, self.move, self.send, self.telemetry)

    def poll(self, tick: int, now_ns: int) -> None:
        self.now_s = self.harness.time_s(now_ns)
        enabled = self.peer.poll(self.now_s)
        if enabled != self.enabled:
            self.enabled = enabled
            if not enabled:  # the servo holds where the tool is (the watchdog's event says why)
                self.hold_m = self.world.tool.position_m.copy()

    def law(self, tick: int, now_ns: int) -> None:
        world = self.world
        fe = world.sense()
        if not self.enabled:
            self.command = (self.hold_m, np.zeros((1, 2)))
            return
        peer, tool = self.peer, world.tool
        self.command = self.pair.slave(fe, tool.position_m, tool.velocity_m_per_s,
                                       peer.message, peer.fresh, peer.outgoing)

    def move(self, tick: int, now_ns: int) -> None:
        self.world.move(*self.command)

    def send(self, tick: int, now_ns: int) -> None:
        self.peer.send(self.enabled)

    def telemetry(self, tick: int, now_ns: int) -> None:
        world = self.world
        fex, fey = world.fe[0].tolist()
        if self.enabled:
            self.max_force_N = max(self.max_force_N, math.hypot(fex, fey))
        if not self.trace.due():
            self.trace.skip()
        else:
            (x, y), (vx, vy) = world.tool.position_m[0].tolist(), (
                world.tool.velocity_m_per_s[0].tolist())
            fh, yh = self._handle()
            self.trace.record((self.now_s, fh[0], fh[1], yh[0], yh[1], x, y, vx, vy, fex, fey,
                               world.engagement, float(world.cutting), float(self.enabled),
                               tick * self.harness.period_s))
            self.tool_path.add(x, y)
        self.harness.status(tick, now_ns, self.peer.watchdog,
                            (self.peer.watchdog.events, self.events),
                            forces_enabled=self.enabled)

    def _handle(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """The handle's force (N) and position (m) where the law's handle message carries
        them (four-channel: both; model-mediated: the position), else NaN."""
        values = self.peer.message[0]
        if self.control.startswith("four-channel"):
            return (float(values[4]), float(values[5])), (float(values[0]), float(values[1]))
        if self.control == "mmt":
            return _NAN2, (float(values[0]), float(values[1]))
        return _NAN2, _NAN2

    def stop_safely(self) -> None:
        """The tool stops where it is; the master is told (SAFE_STATE | STOPPING)."""
        try:
            self.world.tool.velocity_m_per_s[...] = 0.0
            self.peer.send_stop()
        except Exception as error:  # noqa: BLE001 - shutting down regardless
            self.harness.say(f"while stopping: {error}")

    def status_text(self) -> str:
        return self.harness.status_line(
            self.peer.watchdog, f"fe {self.world.fe[0, 0]:+.2f} N  {self.control}")


def run_law_slave(options: Any, control: str, settings: LawSettings, world: LawSlaveWorld,
                  peer_wait_s: float | None, trace_every: int, out: Path | None,
                  extra_summary: dict[str, Any]) -> int:
    """Run the slave's side of ``control`` until the duration ends or SIGINT/SIGTERM;
    returns the exit status (0; 1 when no master came within ``peer_wait_s``). Raises
    LinkOpenError for a master that runs another control mode (the pairing refuses it)."""
    with StopSignals() as signals, LawLink(options.link, control) as link:
        harness = ProgramHarness("haptic-slave", "master", options, link, settings.period_s)
        met = meet_law_peer(harness, link, control, settings, peer_wait_s, signals)
        if isinstance(met, int):
            return met
        pair, peer = met
        trace = TraceRecorder(SLAVE_TRACE_COLUMNS, trace_every)
        stages = LawSlaveStages(control, peer, pair, world, harness, trace)
        driver = TickDriver([stages])
        harness.start()
        run: RunStats = harness.run(driver, stages.status_text, signals, stages.stop_safely)
        summary = harness.summary(
            run, peer.watchdog, stages.max_force_N, (peer.watchdog.events, stages.events),
            stages=driver.stage_times[0].summary(), control=control,
            final_tool_position_m=world.tool.position_m[0].tolist(),
            removed_volume_m3=world.removed_volume_m3,
            **passivity_summary(passivity_port(pair, "slave"), False), **extra_summary)
    traced = trace.arrays()
    on_samples = {**traced, "time_s": traced["sample_time_s"]} if traced else traced
    summary.update(cutting_figures(on_samples))
    summary.update(steady_cut_fields(on_samples))
    if out is not None:
        _save_files(out, summary, world, trace, stages.tool_path, run)
    harness.finish(summary)
    cut = summary.get("cut_mean_force_N")
    if cut is not None:
        print(f"haptic-slave: in the clay {summary['cutting_time_s']:.2f} s: mean |ft| "
              f"{cut:.3f} N, mean speed {summary['cut_mean_speed_m_s'] * 1e3:.1f} mm/s",
              file=sys.stderr, flush=True)
    return 0


def _save_files(out: Path, summary: dict[str, Any], world: LawSlaveWorld,
                trace: TraceRecorder, tool_path: ToolPath, run: RunStats) -> None:
    """``--out DIR``: the trace, and with clay the workpiece and its picture."""
    out.mkdir(parents=True, exist_ok=True)
    trace.save(out / "slave_trace.npz")
    summary["trace"] = str(out / "slave_trace.npz")
    state = world.state
    if hasattr(state, "save_npz"):
        state.save_npz(out / "clay.npz")
        state.render_png(out / "clay.png", tool_path.array(),
                         title=f"{summary['control']}: networked run, {run.elapsed_s:.1f} s")
        summary["clay_npz"] = str(out / "clay.npz")
        summary["clay_png"] = str(out / "clay.png")


__all__ = ["LAW_SLAVE_TICK_STAGES", "LawSlaveStages", "LawSlaveWorld", "run_law_slave"]
