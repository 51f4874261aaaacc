"""The package layers (docs/architecture.md): ``haptic.common`` is the bottom layer and
imports nothing above it; ``master`` and ``slave_sim`` are peers that never import each
other; ``lockstep`` composes both; ``view`` reads what the programs publish. Reading a
configuration loads no CAN stack and no package above ``common``."""

from __future__ import annotations

import ast
import subprocess
import sys
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
