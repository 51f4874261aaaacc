"""Each module's last complete run (``last_scores.toml``): it reads back what it writes,
refuses a malformed file by what is wrong, naming the module, keeps the records a new run did
not touch, and the shipped one loads."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from tools.mutation import changed, last_scores, modules

ROOT = Path(__file__).resolve().parents[2]
COMMIT = "0123456789abcdef0123456789abcdef01234567"
RECORDS = {"master/node.py": last_scores.Scored(COMMIT, "2026-12-06", 0.98765),
           "slave_sim/pacing.py": last_scores.Scored(COMMIT, "2026-12-05", 1.0)}


def test_a_record_reads_back_what_it_writes() -> None:
    back = last_scores.parse(last_scores.render(RECORDS))
    assert list(back) == ["master/node.py", "slave_sim/pacing.py"]
    assert back["master/node.py"] == last_scores.Scored(COMMIT, "2026-12-06", 0.9877)
    assert back["slave_sim/pacing.py"] == RECORDS["slave_sim/pacing.py"]


@pytest.mark.parametrize(("change", "message"), [
    (lambda t: t.replace('date = "2026-12-06"\n', ""), "master/node.py: missing date"),
    (lambda t: t.replace("score = 1.0000", 'score = 1.0\nwhy = "x"'),
     "slave_sim/pacing.py: unknown key(s) why"),
    (lambda t: t.replace(COMMIT, COMMIT[:12], 1), "master/node.py: commit must be"),
    (lambda t: t.replace(COMMIT, COMMIT.upper(), 1), "40 hex digits"),
    (lambda t: t.replace("2026-12-05", "5 Dec 2026"), "pacing.py: date must be YYYY-MM-DD"),
    (lambda t: t.replace("score = 1.0000", "score = 1.5"), "pacing.py: score must be"),
    (lambda t: t.replace("score = 1.0000", "score = true"), "pacing.py: score must be"),
    (lambda t: 'stray = 1\n' + t, "stray: must be a table"),
    (lambda t: t + "[broken\n", "last.toml: "),
])
def test_a_malformed_record_is_refused_saying_what_is_wrong(change, message: str) -> None:
    with pytest.raises(last_scores.RecordError) as caught:
        last_scores.parse(change(last_scores.render(RECORDS)), "last.toml")
    assert str(caught.value).startswith("last.toml: ")
    assert message in str(caught.value)


def test_no_record_file_is_no_record(tmp_path: Path) -> None:
    assert last_scores.load(tmp_path / "absent.toml") == {}


def test_a_new_run_replaces_its_modules_records_and_keeps_the_others() -> None:
    new = {"slave_sim/pacing.py": last_scores.Scored("f" * 40, "2026-12-07", 0.97),
           "common/a.py": last_scores.Scored("f" * 40, "2026-12-07", 1.0)}
    merged = last_scores.updated(RECORDS, new, ["common/a.py", "slave_sim/pacing.py"])
    assert list(merged) == ["common/a.py", "slave_sim/pacing.py", "master/node.py"]
    assert merged["slave_sim/pacing.py"].score == 0.97
    assert merged["master/node.py"] == RECORDS["master/node.py"]


def test_the_empty_tree_is_gits_own() -> None:
    done = subprocess.run(["git", "hash-object", "-t", "tree", "/dev/null"], cwd=ROOT,
                          capture_output=True, text=True, check=True)
    assert done.stdout.strip() == changed.EMPTY_TREE


def test_the_shipped_record_loads_and_scores_configured_modules() -> None:
    # a record below the minimum is kept as it was (the CI mode counts its module as changed)
    records = last_scores.load()
    configured = {c.path for c in modules.load(ROOT)}
    assert records and set(records) <= configured
