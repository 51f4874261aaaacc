"""Making the mutants: cosmic-ray's operators, one plausible replacement per site.

Each mutant is one small change of one module's source (``<`` -> ``<=``, ``+`` -> ``-``, a
number plus one, ``and`` -> ``or``, a condition negated, ...). Type annotations are never
mutated (with ``from __future__ import annotations`` they are not evaluated), nor is a line
ending in :data:`PRAGMA`.
"""

from __future__ import annotations

import ast
import difflib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

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
#: A line ending in this is never mutated (code whose mutants are equivalent by construction).
PRAGMA = "# pragma: no mutate"


@dataclass
class Mutant:
    """One mutation of one module: the whole mutated source, and the mutated line (stripped)
    before and after, with the non-blank line above it (what an equivalent entry keys on)."""

    path: str
    operator: str
    occurrence: int
    line: int
    source: str
    before: str = ""
    after: str = ""
    above: str = ""

    def diff(self, original: str) -> str:
        """A unified diff of ``original`` against the mutated source (no context)."""
        lines = difflib.unified_diff(original.splitlines(True), self.source.splitlines(True),
                                     f"a/{self.path}", f"b/{self.path}", n=0)
        return "".join(lines)


def _keep(operator: str, index_at_node: int) -> bool:
    """One mutant per site: NumberReplacer offers +1 and -1, keep +1."""
    return not (operator == "core/NumberReplacer" and index_at_node > 0)


def annotation_spans(source: str) -> list[tuple[tuple[int, int], tuple[int, int]]]:
    """(start, end) positions (line, column) of every type annotation of ``source``."""
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


def _mutate(source: str, operator: object, occurrence: int) -> str | None:
    """cosmic-ray's mutation ``occurrence`` of ``operator``; None where it cannot make it."""
    from cosmic_ray.mutating import MutationVisitor

    try:
        mutated = MutationVisitor.mutate_code(source, operator, occurrence)
    except AttributeError:
        # cosmic-ray's ExceptionReplacer cannot replace a dotted name in an except clause
        # (``except (can.CanError, OSError)``): not made
        return None
    return None if mutated == source else mutated


def mutants(root: Path, path: str,
            keep_line: Callable[[str], bool] | None = None) -> list[Mutant]:
    """Every mutant of ``path`` (relative to ``root``), sorted by line, operator and
    occurrence; with ``keep_line``, only those of the lines (stripped) it keeps: the same
    mutants, without making the others (each is a whole re-parse of the file)."""
    from cosmic_ray.ast import ast_nodes, get_ast
    from cosmic_ray.plugins import get_operator

    source = (root / path).read_text()
    lines = source.splitlines()
    annotations = annotation_spans(source)
    nodes = list(ast_nodes(get_ast(source)))  # read only: one parse serves every operator
    found = []
    for name in OPERATORS:
        operator = get_operator(name)()
        occurrence = 0
        for node in nodes:
            for index, (start, _end) in enumerate(operator.mutation_positions(node)):
                line = start[0]
                text = lines[line - 1]
                if (_keep(name, index) and not text.rstrip().endswith(PRAGMA)
                        and (keep_line is None or keep_line(text.strip()))
                        and not any(a <= start < b for a, b in annotations)
                        and (mutated := _mutate(source, operator, occurrence)) is not None):
                    above = next((t.strip() for t in reversed(lines[:line - 1]) if t.strip()),
                                 "")
                    found.append(Mutant(path, name, occurrence, line, mutated, text.strip(),
                                        mutated.splitlines()[line - 1].strip(), above))
                occurrence += 1
    found.sort(key=lambda m: (m.line, m.operator, m.occurrence))
    return found
