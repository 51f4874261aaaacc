"""The mutants made: one-line changes that compile, never of an annotation."""

from __future__ import annotations

import ast
from pathlib import Path

from tools.mutation.mutants import mutants

ROOT = Path(__file__).resolve().parents[2]


def test_mutants_are_one_line_changes_that_compile_and_skip_annotations() -> None:
    found = mutants(ROOT, "common/runtime/watchdog.py")
    original = (ROOT / "common/runtime/watchdog.py").read_text().splitlines()
    assert len(found) > 30
    for mutant in found:
        lines = mutant.source.splitlines()
        assert len(lines) == len(original)
        changed = [i for i, (a, b) in enumerate(zip(original, lines, strict=True)) if a != b]
        assert changed == [mutant.line - 1], mutant.operator
        ast.parse(mutant.source)
    # the annotation "str | None" of _trip's signature is never mutated
    node_mutants = mutants(ROOT, "master/node.py", lambda line: line.startswith("def _trip("))
    assert not any(m.before.startswith("def _trip(") and "&" in m.after for m in node_mutants)
    assert "core/ReplaceComparisonOperator_Gt_GtE" in {m.operator for m in found}


def test_a_line_filter_makes_the_same_mutants_of_those_lines() -> None:
    every = mutants(ROOT, "common/runtime/watchdog.py")
    wanted = {m.before for m in every[::7]}
    filtered = mutants(ROOT, "common/runtime/watchdog.py", wanted.__contains__)
    assert [(m.line, m.operator, m.occurrence, m.source) for m in filtered] == [
        (m.line, m.operator, m.occurrence, m.source) for m in every if m.before in wanted]


def test_a_pragma_line_is_not_mutated(tmp_path: Path) -> None:
    (tmp_path / "m.py").write_text("a = 1 + 2\nb = 3 + 4  # pragma: no mutate\n")
    found = mutants(tmp_path, "m.py")
    assert found and {m.line for m in found} == {1}
