"""Which configured modules a change touched (the CI mode, ``--changed-since [REF]``).

A change is ``git diff REF`` in the working tree: the files changed since ``REF``, committed
or not. Without ``REF`` it is, module by module, the change since that module's last complete
run (``last_scores.toml``'s commit for it, when the clone has it), so a clean clone of main,
whose merge base with main is HEAD itself, still has one. A configured module is touched when
its own file changed or one of its test files did (a weakened test lowers its score as surely
as new code does). The touched modules run the newest change first, so a time box spends
itself on what changed last.
"""

from __future__ import annotations

import subprocess
from collections.abc import Callable, Iterable
from pathlib import Path

#: git's empty tree: as a base, every file of HEAD is part of the change; to
#: :func:`recency`, HEAD's whole history counts.
EMPTY_TREE = "4b825dc642cb6eb9a060e54bf8d69288fbee4904"


class GitError(RuntimeError):
    """git failed (not a repository, an unknown revision); the message has git's own words."""


def _git(root: Path, *args: str) -> str:
    """git's standard output for ``args`` in ``root``; GitError when it fails."""
    done = subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True,
                          check=False)
    if done.returncode != 0:
        raise GitError(f"git {' '.join(args)}: {done.stderr.strip() or done.returncode}")
    return done.stdout


def _is_commit(root: Path, ref: str) -> bool:
    try:
        _git(root, "rev-parse", "--verify", "--quiet", f"{ref}^{{commit}}")
    except GitError:
        return False
    return True


def default_base(root: Path, recorded: str | None = None) -> str:
    """The commit a change is measured from, as a commit id: ``recorded`` (a module's
    recorded commit) when it is HEAD or an ancestor of it; else ``HEAD~1`` (the last commit is
    the change: a clone without that history); git's empty tree when HEAD has no parent
    either (a first commit, a shallow clone): then every file is part of the change."""
    if recorded is not None and _is_commit(root, recorded):
        try:
            _git(root, "merge-base", "--is-ancestor", recorded, "HEAD")
            return _git(root, "rev-parse", recorded).strip()
        except GitError:
            pass
    try:
        return _git(root, "rev-parse", "--verify", "--quiet", "HEAD~1").strip()
    except GitError:
        return EMPTY_TREE


def changed_files(root: Path, ref: str) -> set[str]:
    """The files (relative to the repository's top) that differ between ``ref`` and the
    working tree; GitError for an unknown ``ref``."""
    return {line for line in _git(root, "diff", "--name-only", "--no-renames", ref,
                                  "--").splitlines() if line}


def recency(root: Path, ref: str) -> dict[str, int]:
    """How recently each file changed since ``ref``: 0 for a change not committed, n for a
    file the n-th newest commit after ``ref`` changed last (from the whole history of HEAD
    when ``ref`` is no commit: the empty tree)."""
    rank = dict.fromkeys(_git(root, "diff", "--name-only", "--no-renames", "HEAD",
                              "--").splitlines(), 0)
    span = f"{ref}..HEAD" if _is_commit(root, ref) else "HEAD"
    number = 0
    for line in _git(root, "log", "--no-renames", "--name-only", "--format=%x01",
                     span, "--").splitlines():
        if line == "\x01":
            number += 1
        elif line:
            rank.setdefault(line, number)
    return rank


def touched(modules: Iterable[str], changed: set[str],
            tests_of: Callable[[str], Iterable[str]]) -> list[str]:
    """The ``modules`` (in their order) whose file is in ``changed`` or one of whose tests
    (``tests_of(module)``) is."""
    return [m for m in modules if m in changed or any(t in changed for t in tests_of(m))]


def newest_first(modules: Iterable[str], rank: dict[str, int],
                 tests_of: Callable[[str], Iterable[str]]) -> list[str]:
    """``modules`` ordered by their newest change (of the module or one of its tests, by
    ``rank``: :func:`recency`), then by their own file's (an integration test changed
    touches many modules at once), then in their given order."""
    unranked = len(rank) + 1

    def newest(module: str) -> tuple[int, int]:
        own = rank.get(module, unranked)
        return min([own, *(rank.get(test, unranked) for test in tests_of(module))]), own

    return sorted(modules, key=newest)  # stable: ties keep the given order


def head(root: Path) -> str:
    """HEAD's commit id."""
    return _git(root, "rev-parse", "HEAD").strip()


def uncommitted(root: Path) -> list[str]:
    """The tracked files whose working copy differs from HEAD, sorted."""
    return sorted(line for line in _git(root, "diff", "--name-only", "HEAD", "--").splitlines()
                  if line)
