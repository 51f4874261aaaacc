"""The package layers (docs/architecture.md): ``haptic.common`` is the bottom layer and
imports nothing above it; ``master`` and ``slave_sim`` are peers that never import each
other; ``lockstep`` composes both; ``view`` reads what the programs publish. Reading a
configuration loads no CAN stack and no package above ``common``. Every function does one job
(at most 80 lines; a program module's nested functions at most 30), and no docstring or comment
holds a date, a machine or an issue number."""

from __future__ import annotations

import ast
import io
import re
import subprocess
import sys
import tokenize
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

#: package folder -> the haptic packages it may import (besides itself)
ALLOWED = {
    "common": set(),
    "master": {"common"},
    "slave_sim": {"common"},
    "lockstep": {"common", "master", "slave_sim"},
    "view": {"common", "slave_sim"},
}


def _imported_names(path: Path) -> list[tuple[list[str], int]]:
    """The dotted parts and line of every absolute import in a module, lazy imports included."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found += [(alias.name.split("."), node.lineno) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.append((node.module.split("."), node.lineno))
    return found


def _haptic_imports(path: Path) -> set[tuple[str, int]]:
    """(top haptic package, line) of every import in a module."""
    return {(parts[1], line) for parts, line in _imported_names(path)
            if parts[0] == "haptic" and len(parts) > 1}


@pytest.mark.parametrize("package", sorted(ALLOWED))
def test_no_package_imports_above_its_layer(package: str) -> None:
    allowed = ALLOWED[package] | {package}
    offences = [
        f"{path.relative_to(ROOT)}:{line} imports haptic.{target}"
        for path in sorted((ROOT / package).rglob("*.py"))
        for target, line in sorted(_haptic_imports(path))
        if target not in allowed
    ]
    assert not offences, "\n".join(offences)


#: common's subpackages, lowest first: each imports only those before it, so common/ has no
#: import cycle (the model is numbers only; the configuration validates against the model;
#: the records are files; the wire reads its [link] table; the runtime paces and supervises a
#: program over the wire; the analysis and haptic-analyze use them all; the launcher is last)
COMMON_LAYERS = ("model", "control", "config", "records", "wire", "ros2", "runtime", "analysis",
                 "launch")


def _common_imports(path: Path) -> set[tuple[str, int]]:
    """(common subpackage, line) of every ``haptic.common.<sub>...`` import in a module."""
    return {(parts[2], line) for parts, line in _imported_names(path)
            if parts[:2] == ["haptic", "common"] and len(parts) > 2}


@pytest.mark.parametrize("sub", COMMON_LAYERS)
def test_each_common_subpackage_imports_only_the_layers_below_it(sub: str) -> None:
    below = set(COMMON_LAYERS[: COMMON_LAYERS.index(sub)])
    offences = [
        f"{path.relative_to(ROOT)}:{line} imports haptic.common.{target}"
        for path in sorted((ROOT / "common" / sub).rglob("*.py"))
        for target, line in sorted(_common_imports(path))
        if target != sub and target not in below
    ]
    assert not offences, "\n".join(offences)


def test_every_common_subpackage_has_a_layer() -> None:
    folders = {p.name for p in (ROOT / "common").iterdir() if (p / "__init__.py").exists()}
    assert folders == set(COMMON_LAYERS)


def test_the_subpackage_checker_sees_a_forbidden_import(tmp_path: Path) -> None:
    module = tmp_path / "m.py"
    module.write_text("from haptic.common.wire.link import Link\n")
    assert ("wire", 1) in _common_imports(module)


#: source folder -> the package it is installed as (pyproject.toml's package-dir)
PACKAGE_DIRS = {"common": "haptic.common", "master": "haptic.master",
                "slave_sim": "haptic.slave_sim", "lockstep": "haptic.lockstep",
                "view": "haptic.view"}


def _module_files(root: Path = ROOT) -> dict[str, Path]:
    """Every source module, by its dotted ``haptic.*`` name (a package by its ``__init__``)."""
    modules = {}
    for folder, package in PACKAGE_DIRS.items():
        for path in (root / folder).rglob("*.py"):
            parts = list(path.relative_to(root / folder).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            modules[".".join([package, *parts])] = path
    return modules


def _module_imports(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """The source modules ``name`` imports (lazy imports included; ``from pkg import mod``
    counts as importing ``mod``), resolved to the longest module name that exists."""

    def resolve(dotted: str) -> str | None:
        parts = dotted.split(".")
        for end in range(len(parts), 0, -1):
            if ".".join(parts[:end]) in modules:
                return ".".join(parts[:end])
        return None

    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        targets = []
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(package[:len(package) - node.level + 1] + ([base] if base else []))
            targets = [base] + [f"{base}.{alias.name}" for alias in node.names]
        found |= {resolve(t) for t in targets if t.startswith("haptic.")}
    return found - {None, name}


def import_cycles(modules: dict[str, Path]) -> list[list[str]]:
    """The groups of modules that import each other, directly or around a loop (strongly
    connected components of more than one module, Tarjan's algorithm)."""
    edges = {name: _module_imports(name, path, modules) for name, path in modules.items()}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    cycles: list[list[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        for target in edges[node]:
            if target not in index:
                visit(target)
                low[node] = min(low[node], low[target])
            elif target in stack:
                low[node] = min(low[node], index[target])
        if low[node] == index[node]:
            group = []
            while True:
                member = stack.pop()
                group.append(member)
                if member == node:
                    break
            if len(group) > 1:
                cycles.append(sorted(group))

    for name in sorted(modules):
        if name not in index:
            visit(name)
    return cycles


def test_no_two_modules_import_each_other() -> None:
    cycles = import_cycles(_module_files())
    assert not cycles, "modules in an import cycle:\n" + "\n".join(map(str, cycles))


def test_the_cycle_checker_sees_a_loop_of_three_and_a_relative_import(tmp_path: Path) -> None:
    (tmp_path / "common").mkdir()
    for folder in PACKAGE_DIRS:
        (tmp_path / folder).mkdir(exist_ok=True)
    (tmp_path / "common" / "a.py").write_text("from haptic.common.b import x\n")
    (tmp_path / "common" / "b.py").write_text("def f():\n    import haptic.common.c\n")
    (tmp_path / "common" / "c.py").write_text("from . import a\n")
    (tmp_path / "common" / "d.py").write_text("from haptic.common import a\n")
    cycles = import_cycles(_module_files(tmp_path))
    assert cycles == [["haptic.common.a", "haptic.common.b", "haptic.common.c"]]


def test_the_checker_sees_a_forbidden_import(tmp_path: Path) -> None:
    module = tmp_path / "m.py"
    module.write_text("def f():\n    from haptic.master.node import MasterNode\n")
    assert ("master", 2) in _haptic_imports(module)


def test_reading_the_configuration_loads_no_can_stack_and_no_master() -> None:
    code = ("import sys\nfrom haptic.common.config import load_config\nload_config()\n"
            "print(sorted(m for m in sys.modules if m.split('.')[0] in "
            "('can', 'canopen', 'cantools', 'warp', 'zenoh') or m.startswith('haptic.') "
            "and not m.startswith('haptic.common')))")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            timeout=120, check=True)
    assert result.stdout.strip() == "[]"


def test_the_rig_names_of_the_schema_are_the_registered_backends() -> None:
    from haptic.common.config.master_schema import RIG_BACKENDS
    from haptic.master.hardware.interface import hardware_names

    assert tuple(sorted(RIG_BACKENDS)) == hardware_names()


def test_the_program_harness_loads_no_can_stack_no_warp_and_no_program() -> None:
    """The harness both programs share (common/runtime/program_harness.py) is ``common``: the slave
    host loads it without python-can, and neither program's package comes with it."""
    code = ("import sys\nimport haptic.common.runtime.program_harness\n"
            "print(sorted(m for m in sys.modules if m.split('.')[0] in "
            "('can', 'canopen', 'cantools', 'warp') or m.startswith('haptic.') "
            "and not m.startswith('haptic.common')))")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            timeout=120, check=True)
    assert result.stdout.strip() == "[]"


def test_every_program_is_a_cli_module_with_main() -> None:
    """Each entry point is ``<package>/cli.py``'s ``main(argv) -> int`` (docs/architecture.md)."""
    import importlib
    import inspect
    import tomllib

    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    assert len(scripts) >= 10
    for program, target in scripts.items():
        module_name, _, function = target.partition(":")
        assert module_name.endswith(".cli") and function == "main", f"{program} -> {target}"
        main = importlib.import_module(module_name).main
        parameters = list(inspect.signature(main).parameters)
        assert parameters == ["argv"], f"{program}: main{parameters}"
        assert inspect.signature(main).return_annotation in (int, "int"), program


#: The folders whose Python the size and prose checks below read.
SOURCE_FOLDERS = ("common", "master", "slave_sim", "lockstep", "view", "bench", "tools")

#: The most lines (``def`` to its last line) a function or method may span: longer ones do
#: more than one job and belong in functions of one job each.
LONGEST_FUNCTION_LINES = 80

#: The most lines a function nested in a program module's function may span: a long closure
#: hides a program's steps from its tests.
LONGEST_NESTED_FUNCTION_LINES = 30

#: The program modules (patterns under the repository root): the nested-function check reads
#: these.
PROGRAM_MODULES = ("master/program*.py", "master/standalone.py", "slave_sim/program*.py",
                   "common/launch/*.py", "lockstep/real_link.py")

#: (path, qualified name) -> why it is still longer than LONGEST_FUNCTION_LINES. Only
#: functions being split now; an entry leaves once its function is short (a test says so).
LONG_FUNCTIONS_BEING_SPLIT: dict[tuple[str, str], str] = {}

#: (path, qualified name) -> why a program module's nested function is still longer than
#: LONGEST_NESTED_FUNCTION_LINES; shrinks like LONG_FUNCTIONS_BEING_SPLIT.
LONG_NESTED_FUNCTIONS_BEING_SPLIT: dict[tuple[str, str], str] = {}


def _source_files(root: Path = ROOT) -> list[Path]:
    """Every Python file of the source folders."""
    return sorted(path for folder in SOURCE_FOLDERS for path in (root / folder).rglob("*.py"))


def function_spans(path: Path) -> list[tuple[str, int, int]]:
    """(qualified name, nesting depth, lines from ``def`` to the last line) of every function
    and method in a module; depth 0 for a module's functions and a class's methods, 1 and more
    for a function defined in a function."""
    spans: list[tuple[str, int, int]] = []

    def visit(node: ast.AST, prefix: str, depth: int) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                name = prefix + child.name
                spans.append((name, depth, child.end_lineno - child.lineno + 1))
                visit(child, name + ".", depth + 1)
            elif isinstance(child, ast.ClassDef):
                visit(child, prefix + child.name + ".", depth)
            else:
                visit(child, prefix, depth)

    visit(ast.parse(path.read_text(), str(path)), "", 0)
    return spans


def _long_functions(paths: list[Path], most_lines: int, nested_only: bool,
                    root: Path = ROOT) -> dict[tuple[str, str], int]:
    """(path, qualified name) -> lines of each function longer than ``most_lines``."""
    return {(path.relative_to(root).as_posix(), name): lines
            for path in paths for name, depth, lines in function_spans(path)
            if lines > most_lines and (depth > 0 or not nested_only)}


def _program_modules(root: Path = ROOT) -> list[Path]:
    """The files PROGRAM_MODULES names that exist."""
    return sorted({path for pattern in PROGRAM_MODULES for path in root.glob(pattern)})


@pytest.fixture(scope="module")
def long_functions() -> dict[tuple[str, str], int]:
    """The source files' functions over the limit, read once for the two tests using them."""
    return _long_functions(_source_files(), LONGEST_FUNCTION_LINES, nested_only=False)


@pytest.fixture(scope="module")
def long_nested_functions() -> dict[tuple[str, str], int]:
    """The program modules' nested functions over their limit, read once."""
    return _long_functions(_program_modules(), LONGEST_NESTED_FUNCTION_LINES, nested_only=True)


def test_no_function_is_longer_than_the_limit(
        long_functions: dict[tuple[str, str], int]) -> None:
    long = long_functions
    offences = [f"{path}: {name} spans {lines} lines (at most {LONGEST_FUNCTION_LINES})"
                for (path, name), lines in sorted(long.items())
                if (path, name) not in LONG_FUNCTIONS_BEING_SPLIT]
    assert not offences, "\n".join(offences)


def test_no_program_module_nests_a_long_function(
        long_nested_functions: dict[tuple[str, str], int]) -> None:
    long = long_nested_functions
    offences = [f"{path}: nested {name} spans {lines} lines "
                f"(at most {LONGEST_NESTED_FUNCTION_LINES})"
                for (path, name), lines in sorted(long.items())
                if (path, name) not in LONG_NESTED_FUNCTIONS_BEING_SPLIT]
    assert not offences, "\n".join(offences)


def test_the_long_function_allowlists_hold_only_long_functions(
        long_functions: dict[tuple[str, str], int],
        long_nested_functions: dict[tuple[str, str], int]) -> None:
    """An entry whose function is now short (or gone) leaves its allowlist, so the lists
    shrink to empty."""
    long, nested = long_functions, long_nested_functions
    stale = [f"LONG_FUNCTIONS_BEING_SPLIT{key}" for key in LONG_FUNCTIONS_BEING_SPLIT
             if key not in long]
    stale += [f"LONG_NESTED_FUNCTIONS_BEING_SPLIT{key}"
              for key in LONG_NESTED_FUNCTIONS_BEING_SPLIT if key not in nested]
    assert not stale, "short now (or gone), remove from the allowlist:\n" + "\n".join(stale)


def test_the_size_checker_sees_a_long_method_and_a_long_nested_function(tmp_path: Path) -> None:
    module = tmp_path / "m.py"
    body = "".join(f"        x{i} = {i}\n" for i in range(31))
    module.write_text("class C:\n    def outer(self):\n        def inner():\n"
                      + body.replace("        ", "            ") + "        return inner\n")
    long = _long_functions([module], 30, nested_only=False, root=tmp_path)
    assert long == {("m.py", "C.outer"): 34, ("m.py", "C.outer.inner"): 32}
    assert set(_long_functions([module], 30, nested_only=True, root=tmp_path)) == {
        ("m.py", "C.outer.inner")}


#: What no source docstring or comment says: a date, a machine's name or size, an issue's
#: number. Measured figures with their machine and date live in docs/measurements/; the
#: reasons for the code stay in the code.
DATED_OR_MACHINE_PROSE = re.compile(
    r"\b20\d\d-\d\d-\d\d\b|\bissues? #?\d+|(?<![\w#&])#\d+\b|\bXeon\b|\bEPYC\b"
    r"|\bdevelopment VM\b|\b\d+-core\b", re.IGNORECASE)

#: path -> why its docstrings or comments still hold such prose: only files being cleaned
#: now; an entry leaves once its file is clean (a test says so).
PROSE_BEING_CLEANED: dict[str, str] = {}


def dated_or_machine_prose(path: Path) -> list[tuple[int, str]]:
    """(line, matched text) of every date, machine name or issue number in a module's comments
    and docstrings (every string that stands alone as a statement: module, class, function
    and attribute docstrings)."""
    text = path.read_text()
    found = [(token.start[0], match.group())
             for token in tokenize.generate_tokens(io.StringIO(text).readline)
             if token.type == tokenize.COMMENT
             for match in DATED_OR_MACHINE_PROSE.finditer(token.string)]
    found += [(node.lineno, match.group())
              for node in ast.walk(ast.parse(text, str(path)))
              if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant)
              and isinstance(node.value.value, str)
              for match in DATED_OR_MACHINE_PROSE.finditer(node.value.value)]
    return sorted(found)


def _files_with_dated_or_machine_prose() -> dict[str, list[tuple[int, str]]]:
    """path -> its findings, for each source file with any."""
    found = {path.relative_to(ROOT).as_posix(): dated_or_machine_prose(path)
             for path in _source_files()}
    return {path: hits for path, hits in found.items() if hits}


@pytest.fixture(scope="module")
def prose_found() -> dict[str, list[tuple[int, str]]]:
    """The source files' dated or machine prose, read once for the two tests using it."""
    return _files_with_dated_or_machine_prose()


def test_no_docstring_or_comment_holds_a_date_a_machine_or_an_issue_number(
        prose_found: dict[str, list[tuple[int, str]]]) -> None:
    offences = [f"{path}:{line}: {text!r}"
                for path, hits in sorted(prose_found.items())
                if path not in PROSE_BEING_CLEANED for line, text in hits]
    assert not offences, ("dates, machines and issue numbers belong in docs/measurements/ or "
                          "the commit message:\n" + "\n".join(offences))


def test_the_prose_allowlist_holds_only_files_with_such_prose(
        prose_found: dict[str, list[tuple[int, str]]]) -> None:
    found = prose_found
    stale = [path for path in PROSE_BEING_CLEANED if path not in found]
    assert not stale, "clean now (or gone), remove from PROSE_BEING_CLEANED: " + ", ".join(stale)


def test_the_prose_checker_sees_a_date_a_machine_and_an_issue(tmp_path: Path) -> None:
    module = tmp_path / "m.py"
    module.write_text('"""Fast on a 2-core Xeon."""\n\n\ndef f():\n    """See issue 16."""\n'
                      "    return 1  # measured 2026-12-05, #12\n\n\n"
                      'LABEL = "issue 3 in a string is data"\n')
    assert dated_or_machine_prose(module) == [(1, "2-core"), (1, "Xeon"), (5, "issue 16"),
                                              (6, "#12"), (6, "2026-12-05")]
