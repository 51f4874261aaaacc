"""What a plain (non-editable) install ships: every source package of the tree is listed in
pyproject.toml, so a wheel holds what the console scripts import (deploy/README.md installs
with ``pip install /path/to/haptic-teleop`` or a built wheel, not ``-e``)."""

from __future__ import annotations

import importlib.util
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _setuptools() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]


def _tree_packages() -> set[str]:
    """Every ``haptic.*`` package of the source tree (a folder with an ``__init__.py`` under
    a mapped root)."""
    found = set()
    for name, folder in _setuptools()["package-dir"].items():
        for init in (ROOT / folder).rglob("__init__.py"):
            if "__pycache__" in init.parts:
                continue
            relative = init.parent.relative_to(ROOT / folder)
            found.add(".".join([name, *relative.parts]))
    return found


def test_every_package_of_the_tree_is_listed() -> None:
    listed = set(_setuptools()["packages"])
    missing = sorted(_tree_packages() - listed)
    assert not missing, f"packages not in pyproject.toml (left out of a wheel): {missing}"
    assert listed <= _tree_packages(), "pyproject.toml lists a package the tree lacks"


def test_every_console_script_imports_from_a_listed_package() -> None:
    """Each ``[project.scripts]`` target's module is in a listed package and exists."""
    listed = set(_setuptools()["packages"])
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    assert "haptic-router" in scripts and "haptic-replay" in scripts
    for script, target in scripts.items():
        module = target.partition(":")[0]
        assert module.rpartition(".")[0] in listed, f"{script}: {module} is not shipped"
        assert importlib.util.find_spec(module) is not None, f"{script}: no {module}"
