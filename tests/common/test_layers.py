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


def _haptic_imports(path: Path) -> set[tuple[str, int]]:
    """(top haptic package, line) of every import in a module, lazy imports included."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        names: list[str] = []
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names = [node.module]
        for name in names:
            parts = name.split(".")
            if parts[0] == "haptic" and len(parts) > 1:
                found.add((parts[1], node.lineno))
    return found


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
    from haptic.master.hardware import hardware_names

    assert tuple(sorted(RIG_BACKENDS)) == hardware_names()


def test_the_program_harness_loads_no_can_stack_no_warp_and_no_program() -> None:
    """The harness both programs share (common/program_harness.py) is ``common``: the slave
    host loads it without python-can, and neither program's package comes with it."""
    code = ("import sys\nimport haptic.common.program_harness\n"
            "print(sorted(m for m in sys.modules if m.split('.')[0] in "
            "('can', 'canopen', 'cantools', 'warp') or m.startswith('haptic.') "
            "and not m.startswith('haptic.common')))")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            timeout=120, check=True)
    assert result.stdout.strip() == "[]"
