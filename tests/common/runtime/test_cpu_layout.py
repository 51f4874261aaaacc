"""The CPU layouts (common/runtime/cpu_layout.py) are what the two commands do: the session's
``split`` gives each loop a CPU of its own, the loop benchmark's ``partitioned`` puts both
loops on one, and the two ``free`` layouts differ."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from types import ModuleType

from haptic.common.launch.cli import CPU_LAYOUTS, build_parser, session_cpu_args
from haptic.common.runtime.cpu_layout import (
    LOOP_BENCH_LAYOUTS,
    LOOPS_FIFO_ANYWHERE,
    LOOPS_ON_SEPARATE_CPUS,
    LOOPS_SHARING_ONE_CPU,
    SESSION_LAYOUTS,
    SESSION_UNPINNED,
    layout_names,
)

LOOP_BENCH = Path(__file__).resolve().parents[3] / "bench" / "loop_bench.py"


def _loop_bench() -> ModuleType:
    """bench/loop_bench.py as a module (bench/ is scripts, not a package)."""
    spec = importlib.util.spec_from_file_location("loop_bench", LOOP_BENCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _loop_cpu(args: list[str]) -> str:
    return args[args.index("--loop-cpus") + 1]


def test_both_commands_take_their_choices_from_the_one_vocabulary() -> None:
    bench = _loop_bench()
    assert CPU_LAYOUTS == layout_names(SESSION_LAYOUTS) == ("split", "free")
    assert bench.CPU_LAYOUTS == layout_names(LOOP_BENCH_LAYOUTS) == ("partitioned", "free")
    session_option = next(action for action in build_parser()._actions
                          if "--cpu-layout" in action.option_strings)
    assert tuple(session_option.choices) == CPU_LAYOUTS
    assert session_option.default == LOOPS_ON_SEPARATE_CPUS.name
    assert all(layout.command == "haptic-session" for layout in SESSION_LAYOUTS)
    assert all(layout.command == "bench/loop_bench.py" for layout in LOOP_BENCH_LAYOUTS)


def test_split_gives_each_loop_a_cpu_and_partitioned_puts_both_on_one() -> None:
    master, slave = session_cpu_args(LOOPS_ON_SEPARATE_CPUS.name, [0, 1])
    assert _loop_cpu(master) != _loop_cpu(slave)
    bench = _loop_bench()
    # the benchmark gives both programs the same run options: one loop CPU for both
    assert _loop_cpu(bench.cpu_layout_args(LOOPS_SHARING_ONE_CPU.name, [0, 1])) == "1"
    assert bench.slave_layout_args(LOOPS_SHARING_ONE_CPU.name, [0, 1]) != []


def test_the_two_free_layouts_are_not_the_same_layout() -> None:
    assert session_cpu_args(SESSION_UNPINNED.name, [0, 1]) == ([], [])
    fifo_anywhere = _loop_bench().cpu_layout_args(LOOPS_FIFO_ANYWHERE.name, [0, 1])
    assert "--loop-cpus" not in fifo_anywhere and "--rt-priority" in fifo_anywhere
    assert SESSION_UNPINNED.help_text() != LOOPS_FIFO_ANYWHERE.help_text()
