"""Each configured module's last complete mutation run: the commit it scored, when, and how.

``last_scores.toml`` (beside this module) holds one table per module path, each with
``commit`` (the 40-hex commit the sources were at), ``date`` (ISO, UTC) and ``score``
(killed / (killed + survived), 0 to 1). It defines what the CI mode calls a change, module by
module: the commits since that module's own record (:func:`tools.mutation.changed.default_base`).
A configured module with no record, or whose record scores below the minimum, counts as
changed. ``python3 -m tools.mutation --record`` writes the record of each module whose run
completed, on a clean tree, and keeps the others; nobody edits its figures by hand.

A record per module, not one for the whole set: the whole set takes hours on two cores, more
than one sitting of the machine, so a single all-or-nothing record went stale and left the CI
box to rescore modules nobody had touched.
"""

from __future__ import annotations

import re
import tomllib
from dataclasses import dataclass
from pathlib import Path

#: The file beside this module.
DEFAULT_PATH = Path(__file__).resolve().with_name("last_scores.toml")
_KEYS = ("commit", "date", "score")
_COMMIT = re.compile(r"[0-9a-f]{40}")
_DATE = re.compile(r"\d{4}-\d{2}-\d{2}")
_HEADER = (
    "# Each configured module's last complete mutation run, written by `python3 -m",
    "# tools.mutation --record` (tools/mutation/last_scores.py): the CI mode's change for a",
    "# module is the commits since its `commit`. Scores are killed / (killed + survived); do not",
    "# edit them by hand.",
)


class RecordError(ValueError):
    """The record is malformed; the message names the file and what is wrong."""


@dataclass(frozen=True)
class Scored:
    """One module's last complete run: its commit, its date (ISO, UTC) and its score
    (killed / (killed + survived), 0 to 1)."""

    commit: str
    date: str
    score: float


def parse(text: str, source: str = "last_scores.toml") -> dict[str, Scored]:
    """Module path -> its record, from ``text``; RecordError (naming ``source`` and the
    module) for an entry that is no table, a missing or unknown key, a commit that is not 40
    lower-case hex digits, a date not ISO or a score outside 0..1."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise RecordError(f"{source}: {error}") from None
    records: dict[str, Scored] = {}
    for path, entry in data.items():
        where = f"{source}: {path}"
        if not isinstance(entry, dict):
            raise RecordError(f"{where}: must be a table of commit, date and score")
        unknown = sorted(set(entry) - set(_KEYS))
        missing = [key for key in _KEYS if key not in entry]
        if unknown or missing:
            raise RecordError(f"{where}: unknown key(s) {', '.join(unknown)}" if unknown
                              else f"{where}: missing {', '.join(missing)}")
        commit, date, score = entry["commit"], entry["date"], entry["score"]
        if not isinstance(commit, str) or not _COMMIT.fullmatch(commit):
            raise RecordError(f"{where}: commit must be a full commit id (40 hex digits)")
        if not isinstance(date, str) or not _DATE.fullmatch(date):
            raise RecordError(f"{where}: date must be YYYY-MM-DD")
        if not isinstance(score, int | float) or isinstance(score, bool) or not 0 <= score <= 1:
            raise RecordError(f"{where}: score must be from 0 to 1")
        records[path] = Scored(commit, date, float(score))
    return records


def load(path: Path = DEFAULT_PATH) -> dict[str, Scored]:
    """The records in the file at ``path``; none when there is no such file (every
    configured module then counts as changed)."""
    try:
        text = path.read_text()
    except FileNotFoundError:
        return {}
    return parse(text, path.name)


def render(records: dict[str, Scored]) -> str:
    """``records`` as the TOML text :func:`parse` reads back (scores to four decimals), in
    their order."""
    lines = list(_HEADER)
    for path, record in records.items():
        lines += ["", f'["{path}"]', f'commit = "{record.commit}"', f'date = "{record.date}"',
                  f"score = {record.score:.4f}"]
    return "\n".join(lines) + "\n"


def updated(records: dict[str, Scored], new: dict[str, Scored],
            order: list[str]) -> dict[str, Scored]:
    """``records`` with ``new``'s entries replacing or joining theirs, in ``order`` (the
    configured modules' order), then any other path they hold."""
    merged = records | new
    return {path: merged[path] for path in [*order, *(p for p in merged if p not in order)]
            if path in merged}
