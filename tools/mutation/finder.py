"""The test-finder: which test files exercise a module, from what they import.

Static: every ``tests/**/test_*.py`` is parsed (never imported) and each ``haptic.*`` import in
it is collected, the lazy ones inside functions included, as are ``importlib.import_module``
calls with a literal name and the imports of the test helpers it imports (``tests.*``). A name
imported from a package (``from haptic.common.config import load_config``) counts for the
module that defines it when the package's ``__init__`` re-exports it. Module names map to files
through pyproject.toml's ``[tool.setuptools.package-dir]`` (``haptic.master`` -> ``master/``).

A module that no test imports (a kernel module imported only by its node, say) is found
through the modules that import it: the tests of its nearest importers. A module tested
through the modules built on it (a base class's) asks for more: ``depth`` 2 also takes the
tests of the modules that import it.
"""

from __future__ import annotations

import ast
import tomllib
from collections.abc import Iterable
from functools import cache, cached_property
from pathlib import Path

#: Where the tests live, relative to the repository, and which of their files pytest collects.
TESTS_DIR = "tests"
TEST_GLOB = "test_*.py"
#: The top-level package of the project's modules.
PACKAGE = "haptic"


def package_dirs(root: Path) -> dict[str, str]:
    """pyproject.toml's package-dir mapping: ``{"haptic.master": "master", ...}``."""
    with open(root / "pyproject.toml", "rb") as handle:
        return dict(tomllib.load(handle)["tool"]["setuptools"]["package-dir"])


def module_name(path: str, package_dir: dict[str, str]) -> str:
    """``master/node.py`` -> ``haptic.master.node`` (a package's ``__init__.py`` -> the
    package); ValueError for a path in no package of the mapping."""
    folder, _, stem = path.rpartition("/")
    stem = "" if stem == "__init__.py" else stem.removesuffix(".py")
    for package, directory in package_dir.items():
        if folder == directory or folder.startswith(directory + "/"):
            rest = folder[len(directory):].strip("/").replace("/", ".")
            return ".".join(part for part in (package, rest, stem) if part)
    raise ValueError(f"{path} is in no package of pyproject.toml's package-dir")


def module_file(name: str, root: Path, package_dir: dict[str, str]) -> str | None:
    """The file (relative to ``root``) of module ``name``: ``haptic.master.node`` ->
    ``master/node.py``, a package -> its ``__init__.py``; None when there is none."""
    for package, directory in package_dir.items():
        if name == package or name.startswith(package + "."):
            base = "/".join([directory, *name[len(package):].strip(".").split(".")])
            base = base.rstrip("/")
            for candidate in (f"{base}.py", f"{base}/__init__.py"):
                if (root / candidate).is_file():
                    return candidate
            return None
    return None


def _absolute(node: ast.ImportFrom, own: str, is_package: bool) -> str:
    """The module an ``ImportFrom`` names, relative ones resolved against module ``own``."""
    if not node.level:
        return node.module or ""
    parts = own.split(".")
    keep = len(parts) - node.level + (1 if is_package else 0)
    return ".".join([*parts[:keep], *([node.module] if node.module else [])])


def imports_of(source: str, own: str = "", is_package: bool = False) -> set[str]:
    """Every module name ``source`` imports, wherever the import statement is (module level,
    function body, ``if TYPE_CHECKING``); for ``from M import n`` both ``M`` and ``M.n`` (the
    caller keeps the ones that are modules); ``importlib.import_module("literal")`` too.
    ``own`` (the module's own name) resolves relative imports."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = _absolute(node, own, is_package)
            found.add(base)
            found.update(f"{base}.{alias.name}" for alias in node.names if alias.name != "*")
        elif (isinstance(node, ast.Call) and node.args
              and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str)
              and (getattr(node.func, "attr", None) == "import_module"
                   or getattr(node.func, "id", None) in ("import_module", "__import__"))):
            found.add(node.args[0].value)
    return found


class ImportGraph:
    """The ``haptic.*`` imports of the project's modules and tests, read from ``root``."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.package_dir = package_dirs(root)

    @cache  # noqa: B019 -- one graph per run; the cache lives as long as it
    def _reexports(self, package_file: str) -> dict[str, str]:
        """Names a package's ``__init__.py`` imports from its modules: name -> module file."""
        own = module_name(package_file, self.package_dir)
        tree = ast.parse((self.root / package_file).read_text())
        names: dict[str, str] = {}
        for node in tree.body:
            if isinstance(node, ast.ImportFrom):
                target = module_file(_absolute(node, own, True), self.root, self.package_dir)
                if target is not None and target != package_file:
                    for alias in node.names:
                        names[alias.asname or alias.name] = target
        return names

    def _resolve(self, name: str, seen: frozenset[str] = frozenset()) -> set[str]:
        """The module files that importing ``name`` stands for (none outside the project): a
        module's file, or for ``package.attribute`` the module the package's ``__init__``
        takes ``attribute`` from (followed through a package that re-exports it in turn)."""
        if not (name == PACKAGE or name.startswith(PACKAGE + ".")):
            return set()
        found = module_file(name, self.root, self.package_dir)
        if found is not None:
            return {found}
        package, _, attribute = name.rpartition(".")
        init = module_file(package, self.root, self.package_dir)
        if init is None or not init.endswith("__init__.py") or init in seen:
            return set()
        target = self._reexports(init).get(attribute)
        if target is None:
            return set()
        if not target.endswith("__init__.py"):
            return {target}
        further = f"{module_name(target, self.package_dir)}.{attribute}"
        return {target} | self._resolve(further, seen | {init})

    @cache  # noqa: B019
    def module_imports(self, path: str) -> frozenset[str]:
        """The project module files that the module file ``path`` imports (directly)."""
        own = module_name(path, self.package_dir)
        names = imports_of((self.root / path).read_text(), own, path.endswith("__init__.py"))
        return frozenset(file for name in names for file in self._resolve(name)) - {path}

    @cache  # noqa: B019
    def test_imports(self, path: str, seen: frozenset[str] = frozenset()) -> frozenset[str]:
        """The project module files that the test file ``path`` imports, with those of the
        test helpers it imports (``tests.*`` modules)."""
        found: set[str] = set()
        for name in imports_of((self.root / path).read_text()):
            found |= self._resolve(name)
            if name.split(".")[0] == TESTS_DIR:
                helper = name.replace(".", "/") + ".py"
                if (self.root / helper).is_file() and helper not in seen | {path}:
                    found |= self.test_imports(helper, seen | {path})
        return frozenset(found)

    def test_files(self) -> list[str]:
        """Every test file pytest collects, relative to the root, sorted."""
        return sorted(str(p.relative_to(self.root)) for p in
                      (self.root / TESTS_DIR).rglob(TEST_GLOB))

    @cached_property
    def modules(self) -> list[str]:
        """Every module file of the project's packages, relative to the root, sorted."""
        return sorted(str(p.relative_to(self.root)) for directory in self.package_dir.values()
                      for p in (self.root / directory).rglob("*.py"))

    def importers(self, path: str) -> list[str]:
        """The project modules that import module file ``path`` directly."""
        return [module for module in self.modules if path in self.module_imports(module)]


def tests_for(path: str, graph: ImportGraph, depth: int = 1,
              tests: Iterable[str] | None = None) -> list[str]:
    """The test files that import module file ``path`` or, with ``depth`` n > 1, a module
    up to n - 1 imports away from it (2: also the tests of the modules that import it); when
    none does, those of its nearest importers further out. Sorted; empty when no test reaches
    it at all."""
    imported = {test: graph.test_imports(test) for test in (tests or graph.test_files())}
    reached, level, hops = {path}, {path}, 1
    while level:
        found = sorted(test for test, modules in imported.items() if modules & reached)
        if found and hops >= depth:
            return found
        level = {m for module in level for m in graph.importers(module)} - reached
        reached |= level
        hops += 1
    return sorted(test for test, modules in imported.items() if modules & reached)


def _first_token(stem: str) -> str:
    return stem.removeprefix("test_").split("_")[0]


def ordered(path: str, tests: Iterable[str], graph: ImportGraph) -> list[str]:
    """``tests`` of module file ``path``, the likeliest to catch its mutants soonest first:
    the one named exactly for it (``test_passivity.py`` for ``passivity.py``: a time cap on
    the tests must never leave it out), then those named for it (the first word of the test
    file's name is the first word of the module's name or its folder's:
    ``test_config_limits.py`` for ``config/loader.py``), then by how few project modules each
    imports (the unit tests before the integration tests)."""
    folder, _, name = path.rpartition("/")
    stem = name.removesuffix(".py")
    words = {_first_token(stem), folder.rpartition("/")[2]}

    def key(test: str) -> tuple[bool, bool, int, str]:
        test_stem = test.rpartition("/")[2].removesuffix(".py")
        return (test_stem != f"test_{stem}", _first_token(test_stem) not in words,
                len(graph.test_imports(test)), test)

    return sorted(tests, key=key)
