"""The configured modules: which modules are mutation-tested, read from ``modules.toml``.

The file holds ``modules`` (a list of paths relative to the repository, in the order they
run), an optional ``[every]`` table (path -> N: every N-th mutant only, unless ``--all``) and
an optional ``[depth]`` table (path -> N: the tests of the modules up to N - 1 imports away
count too; see :func:`tools.mutation.finder.tests_for`). :func:`load` refuses an unknown key,
a path that is not a file, a duplicate, or a table's entry for a path not listed or below 1.
An optional ``max_test_files`` (an integer >= 1) caps each module's tests at that many files,
the likeliest to catch its mutants first (a module half the suite imports is not tested by all
of it). A count, not a time: the tests a mutant runs, and so its outcome, are the same on any
machine, however slow or busy.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path

#: The file beside this module.
DEFAULT_PATH = Path(__file__).resolve().with_name("modules.toml")


_TABLES = ("every", "depth")


class ModulesError(ValueError):
    """The modules file is malformed; the message names the file and what is wrong."""


@dataclass(frozen=True)
class Configured:
    """One module under mutation: its path, the sampling of its mutants (1: all), the
    import depth its tests are found at and the most test files it takes (None: all of them)."""

    path: str
    every: int = 1
    depth: int = 1
    max_test_files: int | None = None


def parse(text: str, root: Path, source: str = "modules.toml") -> list[Configured]:
    """The configured modules of a modules file's ``text``, in file order; ModulesError for a
    malformed file (naming ``source``)."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise ModulesError(f"{source}: {error}") from None
    unknown = sorted(set(data) - {"modules", "max_test_files", *_TABLES})
    if unknown:
        raise ModulesError(f"{source}: unknown key(s) {', '.join(unknown)}")
    paths = data.get("modules", [])
    if not isinstance(paths, list) or not all(isinstance(p, str) for p in paths):
        raise ModulesError(f"{source}: modules must be a list of paths")
    for path in paths:
        if paths.count(path) > 1:
            raise ModulesError(f"{source}: {path} listed twice")
        if not path.endswith(".py") or not (root / path).is_file():
            raise ModulesError(f"{source}: {path} is no Python file of the repository")
    tables = {name: data.get(name, {}) for name in _TABLES}
    for name, table in tables.items():
        if not isinstance(table, dict):
            raise ModulesError(f"{source}: {name} must be a table")
        for path, n in table.items():
            if path not in paths:
                raise ModulesError(f"{source}: [{name}] {path} is not in modules")
            if not _is_count(n):
                raise ModulesError(f"{source}: [{name}] {path} must be an integer >= 1")
    cap = data.get("max_test_files")
    if cap is not None and not _is_count(cap):
        raise ModulesError(f"{source}: max_test_files must be an integer >= 1")
    return [Configured(path, tables["every"].get(path, 1), tables["depth"].get(path, 1), cap)
            for path in paths]


def _is_count(value: object) -> bool:
    """An integer >= 1 (TOML's booleans excluded)."""
    return isinstance(value, int) and not isinstance(value, bool) and value >= 1


def load(root: Path, path: Path = DEFAULT_PATH) -> list[Configured]:
    """The configured modules of the file at ``path`` (see :func:`parse`)."""
    return parse(path.read_text(), root, path.name)
