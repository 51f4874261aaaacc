"""The last full run: the commit every configured module was last scored at as one run.

``last_full_run.toml`` (beside this module) holds ``commit`` (the 40-hex commit the sources
were at), ``date`` (ISO, UTC), ``total_score`` and a ``[scores]`` table (module path ->
killed / (killed + survived), 0 to 1). It defines what the CI mode calls a change: the
commits since this one (:func:`tools.mutation.changed.default_base`), and a configured module
missing from ``[scores]`` has never been scored in a full run, so it counts as changed too.
``python3 -m tools.mutation --record`` rewrites the file after a complete run of every
configured module on a clean tree; nobody edits its figures by hand.
"""

from __future__ import annotations

import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

#: The file beside this module.
DEFAULT_PATH = Path(__file__).resolve().with_name("last_full_run.toml")
_KEYS = ("commit", "date", "total_score", "scores")
_COMMIT = re.compile(r"[0-9a-f]{40}")
_DATE = re.compile(r"\d{4}-\d{2}-\d{2}")


class FullRunError(ValueError):
    """The record is malformed; the message names the file and what is wrong."""


@dataclass(frozen=True)
class FullRun:
    """One full run: its commit, its date (ISO, UTC), its total score and each module's
    score (killed / (killed + survived), 0 to 1)."""

    commit: str
    date: str
    total_score: float
    scores: dict[str, float] = field(default_factory=dict)


def _score(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and 0 <= value <= 1


def parse(text: str, source: str = "last_full_run.toml") -> FullRun:
    """The record in ``text``; FullRunError (naming ``source``) for a missing or unknown key,
    a commit that is not 40 lower-case hex digits, a date not ISO or a score outside 0..1."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise FullRunError(f"{source}: {error}") from None
    unknown = sorted(set(data) - set(_KEYS))
    missing = [key for key in _KEYS if key not in data]
    if unknown or missing:
        raise FullRunError(f"{source}: unknown key(s) {', '.join(unknown)}" if unknown
                           else f"{source}: missing {', '.join(missing)}")
    if not isinstance(data["commit"], str) or not _COMMIT.fullmatch(data["commit"]):
        raise FullRunError(f"{source}: commit must be a full commit id (40 hex digits)")
    if not isinstance(data["date"], str) or not _DATE.fullmatch(data["date"]):
        raise FullRunError(f"{source}: date must be YYYY-MM-DD")
    scores = data["scores"]
    if not isinstance(scores, dict):
        raise FullRunError(f"{source}: scores must be a table of module path -> score")
    for name, value in (("total_score", data["total_score"]), *scores.items()):
        if not _score(value):
            raise FullRunError(f"{source}: {name} must be a score from 0 to 1")
    return FullRun(data["commit"], data["date"], float(data["total_score"]),
                   {path: float(value) for path, value in scores.items()})


def load(path: Path = DEFAULT_PATH) -> FullRun | None:
    """The record in the file at ``path``; None when there is no such file (no full run
    recorded: every configured module counts as changed)."""
    try:
        text = path.read_text()
    except FileNotFoundError:
        return None
    return parse(text, path.name)


def render(run: FullRun) -> str:
    """The record as the TOML text :func:`parse` reads back (scores to four decimals)."""
    lines = [
        "# The last run of every configured module as one, written by `python3 -m tools.mutation",
        "# --record` (tools/mutation/full_run.py): the CI mode's change is the commits since",
        "# `commit`. Scores are killed / (killed + survived); do not edit them by hand.",
        f'commit = "{run.commit}"',
        f'date = "{run.date}"',
        f"total_score = {run.total_score:.4f}",
        "",
        "[scores]",
        *(f'"{path}" = {score:.4f}' for path, score in run.scores.items()),
    ]
    return "\n".join(lines) + "\n"
