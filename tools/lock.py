"""Regenerate constraints.txt, the lock of every runtime and test dependency for Python 3.11.

Run from anywhere: ``python3 tools/lock.py``. It resolves pyproject.toml's dependencies and
its ``test`` extra with uv (``uv pip compile --universal``: one lock valid on every platform,
with environment markers where a platform needs another version), and writes the result
under a header that records a SHA-256 of the dependency tables it was resolved from, so
``tests/deploy/test_dependency_lock.py`` fails when pyproject.toml changes and the lock does
not. uv is taken from PATH when it is there at ``UV_VERSION``; otherwise it is installed into
a throw-away virtual environment first (the lock's own tool is pinned too).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import shutil
import subprocess
import sys
import tempfile
import tomllib
import venv
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LOCK_PATH = ROOT / "constraints.txt"
UV_VERSION = "0.13.9"
PYTHON_VERSION = "3.11"
EXTRAS = ("test",)
REGENERATE_COMMAND = "python3 tools/lock.py"
HASH_PREFIX = "# pyproject-dependencies-sha256: "


def dependency_tables(pyproject_text: str) -> dict[str, object]:
    """The parts of pyproject.toml that a lock is resolved from: the build requirements, the
    runtime dependencies and every optional-dependency group."""
    data = tomllib.loads(pyproject_text)
    project = data["project"]
    return {
        "build-system.requires": data.get("build-system", {}).get("requires", []),
        "project.dependencies": project.get("dependencies", []),
        "project.optional-dependencies": project.get("optional-dependencies", {}),
        "requires-python": project.get("requires-python", ""),
    }


def dependency_hash(pyproject_text: str) -> str:
    """SHA-256 (hex) of :func:`dependency_tables` in a canonical JSON form."""
    canonical = json.dumps(dependency_tables(pyproject_text), sort_keys=True,
                           separators=(",", ":"))
    return hashlib.sha256(canonical.encode()).hexdigest()


def _uv_command() -> tuple[list[str], tempfile.TemporaryDirectory | None]:
    """A command that runs uv at ``UV_VERSION``, and the temporary folder to clean up."""
    found = shutil.which("uv")
    if found:
        version = subprocess.run([found, "--version"], capture_output=True, text=True).stdout
        if version.split()[1:2] == [UV_VERSION]:
            return [found], None
    scratch = tempfile.TemporaryDirectory(prefix="haptic-lock-")
    env_dir = Path(scratch.name) / "venv"
    venv.EnvBuilder(with_pip=True).create(env_dir)
    python = env_dir / "bin" / "python"
    subprocess.run([str(python), "-m", "pip", "install", "-q", f"uv=={UV_VERSION}"], check=True)
    return [str(python), "-m", "uv"], scratch


def compile_lock(upgrade: bool) -> str:
    """The resolved lock's body (uv's output without its header). The present lock's pins
    are kept where they still satisfy pyproject.toml unless ``upgrade``: adding one
    dependency does not move every other."""
    uv, scratch = _uv_command()
    with tempfile.TemporaryDirectory(prefix="haptic-lock-out-") as out_dir:
        out = Path(out_dir) / "constraints.txt"
        if LOCK_PATH.exists() and not upgrade:
            shutil.copyfile(LOCK_PATH, out)
        extras = [arg for extra in EXTRAS for arg in ("--extra", extra)]
        try:
            subprocess.run(
                [*uv, "pip", "compile", "pyproject.toml", *extras, "--python-version",
                 PYTHON_VERSION, "--universal", "--no-header", "--quiet", "-o", str(out)],
                cwd=ROOT, check=True)
        finally:
            if scratch is not None:
                scratch.cleanup()
        return out.read_text()


def lock_text(body: str, pyproject_text: str) -> str:
    """The lock file: our header, then uv's pins with their ``# via`` annotations."""
    header = [
        "# The locked versions of every runtime and test dependency of haptic-teleop",
        f"# (Python {PYTHON_VERSION}, any platform), resolved by uv {UV_VERSION} from"
        " pyproject.toml.",
        "# Installed by the README's commands with pip's -c; do not edit by hand:",
        f"#    {REGENERATE_COMMAND}",
        f"{HASH_PREFIX}{dependency_hash(pyproject_text)}",
    ]
    return "\n".join(header) + "\n" + body


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--upgrade", action="store_true",
                        help="resolve every package anew instead of keeping the present pins")
    args = parser.parse_args(argv)
    pyproject_text = (ROOT / "pyproject.toml").read_text()
    LOCK_PATH.write_text(lock_text(compile_lock(args.upgrade), pyproject_text))
    print(f"wrote {LOCK_PATH.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
