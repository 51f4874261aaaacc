"""The configured modules: which modules are mutation-tested, read from ``modules.toml``.

The file holds ``modules`` (a list of paths relative to the repository, in the order they
run), an optional ``[every]`` table (path -> N: every N-th mutant only, unless ``--all``) and
an optional ``[depth]`` table (path -> N: the tests of the modules up to N - 1 imports away
count too; see :func:`tools.mutation.finder.tests_for`). :func:`load` refuses an unknown key,
a path that is not a file, a duplicate, or a table's entry for a path not listed or below 1.
An optional ``tests_cap_s`` caps each module's tests: the baseline runs them, the likeliest
first, until that many seconds have passed, and the files it reached are the ones used.
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
    import depth its tests are found at and the cap on their time (None: all of them)."""

    path: str
    every: int = 1
    depth: int = 1
    tests_cap_s: float | None = None


def parse(text: str, root: Path, source: str = "modules.toml") -> list[Configured]:
    """The configured modules of a modules file's ``text``, in file order; ModulesError for a
    malformed file (naming ``source``)."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise ModulesError(f"{source}: {error}") from None
    unknown = sorted(set(data) - {"modules", "tests_cap_s", *_TABLES})
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
            if not isinstance(n, int) or isinstance(n, bool) or n < 1:
                raise ModulesError(f"{source}: [{name}] {path} must be an integer >= 1")
    cap = data.get("tests_cap_s")
    if cap is not None and (not isinstance(cap, int | float) or isinstance(cap, bool)
                            or cap <= 0):
        raise ModulesError(f"{source}: tests_cap_s must be a number of seconds > 0")
    return [Configured(path, tables["every"].get(path, 1), tables["depth"].get(path, 1),
                       None if cap is None else float(cap)) for path in paths]


def load(root: Path, path: Path = DEFAULT_PATH) -> list[Configured]:
    """The configured modules of the file at ``path`` (see :func:`parse`)."""
    return parse(path.read_text(), root, path.name)
