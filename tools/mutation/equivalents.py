"""The equivalent mutants: mutants that cannot change behaviour, kept as data with a reason.

Each ``[[equivalent]]`` entry of the file (``equivalents.toml`` beside this module) names a
mutant the way :mod:`tools.mutation.mutants` makes it: ``module`` (the path), ``operator``
(cosmic-ray's name), ``line`` (the mutated line, stripped), ``mutant`` (that line after the
mutation, stripped), ``above`` (optional: the non-blank line above, stripped, for a line that
occurs more than once) and ``reason`` (one line: why no test can tell it from the original).
Listed mutants are neither run nor counted. :func:`load` refuses a file with an unknown key, a
missing or empty field, a reason over more than one line, an unknown operator or a duplicate,
naming the entry.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path

from .mutants import OPERATORS, Mutant

#: The file beside this module.
DEFAULT_PATH = Path(__file__).resolve().with_name("equivalents.toml")
_REQUIRED = ("module", "operator", "line", "mutant", "reason")
_OPTIONAL = ("above",)


class EquivalentsError(ValueError):
    """The equivalents file is malformed; the message names the file and the entry."""


@dataclass(frozen=True)
class Equivalent:
    """One listed equivalent mutant (the fields of its entry)."""

    module: str
    operator: str
    line: str
    mutant: str
    reason: str
    above: str = ""

    def matches(self, mutant: Mutant) -> bool:
        """Whether ``mutant`` is this entry's mutant."""
        return ((mutant.path, mutant.operator, mutant.before, mutant.after)
                == (self.module, self.operator, self.line, self.mutant)
                and (not self.above or self.above == mutant.above))

    @property
    def key(self) -> tuple[str, ...]:
        return (self.module, self.operator, self.above, self.line, self.mutant)


def _entry(raw: object, where: str) -> Equivalent:
    """One entry, checked; EquivalentsError naming ``where`` otherwise."""
    if not isinstance(raw, dict):
        raise EquivalentsError(f"{where}: not a table")
    unknown = sorted(set(raw) - {*_REQUIRED, *_OPTIONAL})
    if unknown:
        raise EquivalentsError(f"{where}: unknown key(s) {', '.join(unknown)} "
                               f"(known: {', '.join((*_REQUIRED, *_OPTIONAL))})")
    for key in (*_REQUIRED, *_OPTIONAL):
        value = raw.get(key)
        if key in _REQUIRED and value is None:
            raise EquivalentsError(f"{where}: missing {key}")
        if value is not None and (not isinstance(value, str) or not value.strip()):
            raise EquivalentsError(f"{where}: {key} must be a non-empty string")
    if "\n" in raw["reason"]:
        raise EquivalentsError(f"{where}: the reason must be one line")
    if raw["operator"] not in OPERATORS:
        raise EquivalentsError(f"{where}: operator {raw['operator']!r} is not one the runner "
                               "uses")
    return Equivalent(**raw)


def parse(text: str, source: str = "equivalents.toml",
          modules: frozenset[str] | None = None) -> list[Equivalent]:
    """The entries of an equivalents file's ``text``, in file order; EquivalentsError for a
    malformed one (naming ``source``, the entry's number and its mutant), or for an entry of a
    module not in ``modules`` when given."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise EquivalentsError(f"{source}: {error}") from None
    extra = sorted(set(data) - {"equivalent"})
    if extra:
        raise EquivalentsError(f"{source}: unknown top-level key(s) {', '.join(extra)}")
    entries: list[Equivalent] = []
    seen: set[tuple[str, ...]] = set()
    for number, raw in enumerate(data.get("equivalent", []), 1):
        name = ""
        if isinstance(raw, dict):
            name = f" ({raw.get('module', '?')}: {raw.get('line', '?')!r} -> " \
                   f"{raw.get('mutant', '?')!r})"
        where = f"{source}: entry {number}{name}"
        entry = _entry(raw, where)
        if modules is not None and entry.module not in modules:
            raise EquivalentsError(f"{where}: {entry.module} is not a configured module")
        if entry.key in seen:
            raise EquivalentsError(f"{where}: listed twice")
        seen.add(entry.key)
        entries.append(entry)
    return entries


def load(path: Path = DEFAULT_PATH, modules: frozenset[str] | None = None) -> list[Equivalent]:
    """The entries of the equivalents file at ``path`` (see :func:`parse`)."""
    return parse(path.read_text(), path.name, modules)


def reason_for(mutant: Mutant, entries: list[Equivalent]) -> str | None:
    """Why ``mutant`` is equivalent, if an entry lists it; None otherwise."""
    return next((entry.reason for entry in entries if entry.matches(mutant)), None)


def markdown_table(entries: list[Equivalent]) -> str:
    """The entries as a Markdown table (module, line, mutant, reason)."""
    def cell(text: str) -> str:
        return text.replace("|", "\\|")

    rows = ["| module | line | mutant | why it is equivalent |", "|---|---|---|---|"]
    for e in entries:
        where = f"`{cell(e.line)}` (after `{cell(e.above)}`)" if e.above else f"`{cell(e.line)}`"
        rows.append(f"| `{e.module}` | {where} | `{cell(e.mutant)}` | {cell(e.reason)} |")
    return "\n".join(rows)
