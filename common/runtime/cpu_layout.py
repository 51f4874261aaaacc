"""The CPU layouts: where the two programs' loops and their other threads run.

Two commands take ``--cpu-layout``, each with layouts of its own, and their names are not
synonyms:

- ``haptic-session`` (common/launch/cli.py) runs a teleoperation session: its ``split``
  gives **each loop a CPU of its own** (:data:`LOOPS_ON_SEPARATE_CPUS`);
- ``bench/loop_bench.py`` measures the loops over the link as on a rig PC: its
  ``partitioned`` puts **both loops on one CPU**, taking turns by the slave's phase lock
  (:data:`LOOPS_SHARING_ONE_CPU`).

Each has a ``free`` layout too, and those differ as well: the session's sets nothing
(:data:`SESSION_UNPINNED`), the benchmark's runs the loops in SCHED_FIFO on any CPU
(:data:`LOOPS_FIFO_ANYWHERE`). Code names a layout by the constant, never by its bare string;
the strings are the command-line values, kept as the documentation and scripts use them.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class CpuLayout:
    """One ``--cpu-layout`` value of one command and what it does."""

    name: str
    """The command-line value."""
    command: str
    """The command that takes it."""
    loops: str
    """Where the master's and the slave's loop threads run."""
    other_threads: str
    """Where every other thread (Zenoh's, the displays', the emulated drives') runs."""

    def help_text(self) -> str:
        """The layout in one phrase for ``--help``."""
        return f"{self.name}: {self.loops}, {self.other_threads}"


#: haptic-session's default on two CPUs or more.
LOOPS_ON_SEPARATE_CPUS = CpuLayout(
    "split", "haptic-session",
    loops="each loop on a CPU of its own (the master's and its emulated drives on the last, "
    "the slave's under SCHED_FIFO on the first)",
    other_threads="the other threads off the master's CPU")

#: haptic-session with nothing set.
SESSION_UNPINNED = CpuLayout(
    "free", "haptic-session",
    loops="both loops where the kernel puts them, --config's [runner] as it is",
    other_threads="the other threads likewise")

#: bench/loop_bench.py's default for the programs at the configured period.
LOOPS_SHARING_ONE_CPU = CpuLayout(
    "partitioned", "bench/loop_bench.py",
    loops="both loops on the last CPU in SCHED_FIFO, taking turns by the slave's phase lock",
    other_threads="the other threads on the other CPUs")

#: bench/loop_bench.py's layout where both ticks do not fit one CPU's period or nothing
#: phase-locks them (the echo nodes, custom commands).
LOOPS_FIFO_ANYWHERE = CpuLayout(
    "free", "bench/loop_bench.py",
    loops="both loops in SCHED_FIFO on any CPU",
    other_threads="Zenoh's threads in SCHED_FIFO below them, the rest where the kernel puts "
    "them")

#: haptic-session's layouts, its default first.
SESSION_LAYOUTS = (LOOPS_ON_SEPARATE_CPUS, SESSION_UNPINNED)
#: bench/loop_bench.py's layouts, its usual default first.
LOOP_BENCH_LAYOUTS = (LOOPS_SHARING_ONE_CPU, LOOPS_FIFO_ANYWHERE)


def layout_names(layouts: tuple[CpuLayout, ...]) -> tuple[str, ...]:
    """The command-line values of ``layouts``, in order (argparse's choices)."""
    return tuple(layout.name for layout in layouts)


__all__ = ["LOOPS_FIFO_ANYWHERE", "LOOPS_ON_SEPARATE_CPUS", "LOOPS_SHARING_ONE_CPU",
           "LOOP_BENCH_LAYOUTS", "SESSION_LAYOUTS", "SESSION_UNPINNED", "CpuLayout",
           "layout_names"]
