"""The lock (constraints.txt) and pyproject.toml agree, and this environment was installed from
the lock: a dependency added to one and not the other, or a package at another version than
the locked one, fails here with the command that mends it."""

from __future__ import annotations

import importlib.metadata
import importlib.util
import re
from pathlib import Path

import pytest
from packaging.markers import default_environment
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

ROOT = Path(__file__).resolve().parents[2]
LOCK_PATH = ROOT / "constraints.txt"
PROJECT = "haptic-teleop"
PIN = re.compile(r"^(?P<name>[A-Za-z0-9][A-Za-z0-9._-]*)==(?P<version>\S+)\s*(;(?P<marker>.*))?$")
VIA_ONE = re.compile(r"^\s+# via (?P<parent>.+)$")
VIA_LIST = re.compile(r"^\s+#   (?P<parent>.+)$")
RELOCK = "relock with `python3 tools/lock.py`"


def _lock_tool():
    spec = importlib.util.spec_from_file_location("haptic_lock_tool", ROOT / "tools" / "lock.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _pyproject_requirements() -> list[Requirement]:
    import tomllib

    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    extras = project.get("optional-dependencies", {})
    return [Requirement(text) for text in project["dependencies"] + extras.get("test", [])]


def parse_lock(text: str) -> tuple[list[tuple[str, str, str | None]], dict[str, set[str]]]:
    """The lock's pins (name, version, marker or None) and each package's ``# via`` parents
    (canonical names; the project itself as ``haptic-teleop``)."""
    pins: list[tuple[str, str, str | None]] = []
    parents: dict[str, set[str]] = {}
    current: str | None = None
    for line in text.splitlines():
        pinned = PIN.match(line)
        if pinned:
            current = canonicalize_name(pinned["name"])
            marker = pinned["marker"].strip() if pinned["marker"] else None
            pins.append((current, pinned["version"], marker))
            parents.setdefault(current, set())
            continue
        via = VIA_ONE.match(line) or VIA_LIST.match(line)
        if via and current is not None and via["parent"].strip() != "":
            parent = via["parent"].split(" (")[0].strip()
            parents[current].add(canonicalize_name(parent))
    return pins, parents


def _applies(marker: str | None) -> bool:
    from packaging.markers import Marker

    return marker is None or Marker(marker).evaluate(default_environment())


def _locked_here() -> dict[str, str]:
    """The lock's pin of each package for this interpreter and platform."""
    pins, _ = parse_lock(LOCK_PATH.read_text())
    return {name: version for name, version, marker in pins if _applies(marker)}


def test_the_lock_was_resolved_from_this_pyproject() -> None:
    tool = _lock_tool()
    recorded = [line for line in LOCK_PATH.read_text().splitlines()
                if line.startswith(tool.HASH_PREFIX)]
    assert recorded, f"constraints.txt has no dependency hash: {RELOCK}"
    expected = tool.dependency_hash((ROOT / "pyproject.toml").read_text())
    assert recorded[0].removeprefix(tool.HASH_PREFIX) == expected, (
        f"pyproject.toml's dependencies changed since constraints.txt was written: {RELOCK}")


def test_every_dependency_of_pyproject_is_locked_within_its_specifier() -> None:
    locked = _locked_here()
    for requirement in _pyproject_requirements():
        name = canonicalize_name(requirement.name)
        assert name in locked, f"{requirement.name} is in pyproject.toml, not in the lock: {RELOCK}"
        assert requirement.specifier.contains(locked[name], prereleases=True), (
            f"the lock pins {name}=={locked[name]} outside pyproject's {requirement}: {RELOCK}")


def lock_faults(text: str, direct: set[str]) -> list[str]:
    """What is wrong between a lock's text and pyproject's direct dependencies (canonical
    names): a pin the lock takes straight from pyproject.toml that pyproject lacks, and pins
    whose ``# via`` chain never reaches pyproject.toml (added by hand, or left behind)."""
    pins, parents = parse_lock(text)
    faults = [f"the lock takes {name} from pyproject.toml, which lacks it"
              for name, _, _ in pins if PROJECT in parents[name] and name not in direct]
    reached = {PROJECT}
    grew = True
    while grew:
        before = len(reached)
        reached |= {name for name, _, _ in pins if parents[name] & reached}
        grew = len(reached) != before
    faults += [f"{name} is locked but nothing in pyproject.toml needs it"
               for name in sorted({name for name, _, _ in pins} - reached)]
    return faults


def _direct() -> set[str]:
    return {canonicalize_name(r.name) for r in _pyproject_requirements()}


def test_every_locked_package_is_needed_by_pyproject() -> None:
    faults = lock_faults(LOCK_PATH.read_text(), _direct())
    assert not faults, f"{faults}: {RELOCK}"


def test_a_pin_added_by_hand_or_a_dependency_dropped_is_a_fault() -> None:
    text = LOCK_PATH.read_text()
    added = text + "left-pad==1.0\n    # via nobody-we-know\n"
    assert lock_faults(added, _direct()) == [
        "left-pad is locked but nothing in pyproject.toml needs it"]
    assert "the lock takes numpy from pyproject.toml, which lacks it" in lock_faults(
        text, _direct() - {"numpy"})


def _installed_closure() -> dict[str, str]:
    """Every distribution this project and its test extra pull in here, with its version."""
    found: dict[str, str] = {}
    pending = [(PROJECT, ("test",))]
    while pending:
        name, extras = pending.pop()
        distribution = importlib.metadata.distribution(name)
        found[canonicalize_name(name)] = distribution.version
        for text in distribution.requires or []:
            requirement = Requirement(text)
            wanted = [{**default_environment(), "extra": extra} for extra in ("", *extras)]
            if requirement.marker is not None and not any(
                    requirement.marker.evaluate(env) for env in wanted):
                continue
            child = canonicalize_name(requirement.name)
            if child not in found:
                pending.append((child, tuple(requirement.extras)))
    return found


def test_this_environment_holds_the_locked_versions() -> None:
    """The README's test command installs with ``-c constraints.txt``; this is what that
    promises: every installed dependency of the project is at its locked version."""
    try:
        closure = _installed_closure()
    except importlib.metadata.PackageNotFoundError as missing:
        pytest.fail(f"{missing} is required but not installed: run the README's test command")
    locked = _locked_here()
    closure.pop(PROJECT)
    drifted = {name: (version, locked.get(name, "not locked"))
               for name, version in sorted(closure.items()) if version != locked.get(name)}
    assert not drifted, (
        f"installed (left) against locked (right): {drifted}; reinstall with "
        "`python3 -m pip install -c constraints.txt -e \".[test]\"`, or, where pyproject.toml "
        f"changed, {RELOCK}")
