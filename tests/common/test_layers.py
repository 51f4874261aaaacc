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
COMMON_LAYERS = ("model", "config", "records", "wire", "runtime", "analysis", "launch")


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
