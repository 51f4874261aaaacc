"""Which configured modules a change touched (the CI mode, ``--changed-since REF``).

A change is ``git diff REF`` in the working tree: the files changed since ``REF``, committed
or not. A configured module is touched when its own file changed or one of its test files did
(a weakened test lowers its score as surely as new code does).
"""

from __future__ import annotations

import subprocess
from collections.abc import Callable, Iterable
from pathlib import Path

#: The branch a change is measured against when it has a remote.
MAIN_BRANCH = "origin/main"


class GitError(RuntimeError):
    """git failed (not a repository, an unknown revision); the message has git's own words."""


def _git(root: Path, *args: str) -> str:
    """git's standard output for ``args`` in ``root``; GitError when it fails."""
    done = subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True,
                          check=False)
    if done.returncode != 0:
        raise GitError(f"git {' '.join(args)}: {done.stderr.strip() or done.returncode}")
    return done.stdout


def default_base(root: Path) -> str:
    """The merge base of HEAD with :data:`MAIN_BRANCH`, or ``HEAD~1`` when there is no such
    branch (no remote), as a commit id; git's empty tree when HEAD has no parent either (a
    first commit, a shallow clone): then every file is part of the change."""
    try:
        return _git(root, "merge-base", "HEAD", MAIN_BRANCH).strip()
    except GitError:
        pass
    try:
        return _git(root, "rev-parse", "--verify", "--quiet", "HEAD~1").strip()
    except GitError:
        return _git(root, "hash-object", "-t", "tree", "/dev/null").strip()


def changed_files(root: Path, ref: str) -> set[str]:
    """The files (relative to the repository's top) that differ between ``ref`` and the
    working tree; GitError for an unknown ``ref``."""
    return {line for line in _git(root, "diff", "--name-only", "--no-renames", ref,
                                  "--").splitlines() if line}


def touched(modules: Iterable[str], changed: set[str],
            tests_of: Callable[[str], Iterable[str]]) -> list[str]:
    """The ``modules`` (in their order) whose file is in ``changed`` or one of whose tests
    (``tests_of(module)``) is."""
    return [m for m in modules if m in changed or any(t in changed for t in tests_of(m))]
