"""bench/mutation_score.py without running mutants: module names, the mutants it makes, and
the list of equivalent mutants kept in step with the sources."""

from __future__ import annotations

import ast
import importlib.util
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[2] / "bench" / "mutation_score.py"


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("mutation_score", BENCH)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    try:
        spec.loader.exec_module(module)
        yield module
    finally:
        sys.modules.pop(spec.name, None)


def test_module_names_follow_the_package_dir_mapping(bench) -> None:
    assert bench.module_name("master/node.py") == "haptic.master.node"
    assert bench.module_name("common/runtime/watchdog.py") == "haptic.common.runtime.watchdog"
    assert bench.module_name("common/analysis/loop.py") == "haptic.common.analysis.loop"


def test_every_configured_module_and_test_exists(bench) -> None:
    root = BENCH.parents[1]
    for path, target in bench.MODULES.items():
        assert (root / path).is_file(), path
        assert target.tests and all((root / t).is_file() for t in target.tests), path
        assert target.every >= 1


def test_mutants_are_one_line_changes_that_compile_and_skip_annotations(bench) -> None:
    found = bench.mutants("common/runtime/watchdog.py")
    original = (BENCH.parents[1] / "common/runtime/watchdog.py").read_text().splitlines()
    assert len(found) > 30
    for mutant in found:
        lines = mutant.source.splitlines()
        assert len(lines) == len(original)
        changed = [i for i, (a, b) in enumerate(zip(original, lines, strict=True)) if a != b]
        assert changed == [mutant.line - 1], mutant.operator
        ast.parse(mutant.source)
    # the annotation "str | None" of _trip's signature is never mutated
    node_mutants = bench.mutants("master/node.py", lambda line: line.startswith("def _trip("))
    assert not any(m.before.startswith("def _trip(") and "&" in m.after for m in node_mutants)
    operators = {m.operator for m in found}
    assert "core/ReplaceComparisonOperator_Gt_GtE" in operators


def test_a_line_filter_makes_the_same_mutants_of_those_lines(bench) -> None:
    every = bench.mutants("common/runtime/watchdog.py")
    wanted = {m.before for m in every[::7]}
    filtered = bench.mutants("common/runtime/watchdog.py", wanted.__contains__)
    assert [(m.line, m.operator, m.occurrence, m.source) for m in filtered] == [
        (m.line, m.operator, m.occurrence, m.source) for m in every if m.before in wanted]


def test_every_listed_equivalent_mutant_is_still_made(bench) -> None:
    """An entry whose line has changed must be re-examined, not silently kept."""
    made = {}
    for path in {entry[0] for entry in bench.EQUIVALENT}:
        listed = {before.rpartition("\n")[2] for where, before, _, _ in bench.EQUIVALENT
                  if where == path}
        made[path] = bench.mutants(path, listed.__contains__)  # the listed lines' mutants
    def makes(entry: tuple[str, str, str, str], mutant) -> bool:
        above, _, line = entry[1].rpartition("\n")
        return (mutant.before, mutant.after) == (line, entry[2]) and (
            not above or above == mutant.above) and bench.equivalent_reason(mutant) == entry[3]

    # entry by entry: several share a reason, and one left stale must not hide behind another
    stale = [entry[:3] for entry in bench.EQUIVALENT
             if not any(makes(entry, m) for m in made[entry[0]])]
    assert stale == []
    # a line listed with the line above it matches that occurrence only
    kernel = [m for m in made["master/node_kernels.py"] if m.after == "if code > 0:"]
    assert len(kernel) == 3  # the trips' first block, the workspace block, the trip count
    assert [bench.equivalent_reason(m) is None for m in kernel] == [True, False, True]
