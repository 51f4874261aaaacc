"""The record of the last full run (``last_full_run.toml``): it reads back what it writes,
refuses a malformed file by what is wrong, and the shipped one loads."""

from __future__ import annotations

from pathlib import Path

import pytest

from tools.mutation import full_run, modules

ROOT = Path(__file__).resolve().parents[2]

RUN = full_run.FullRun("0123456789abcdef0123456789abcdef01234567", "2026-12-06", 0.9912,
                       {"master/node.py": 0.98765, "slave_sim/pacing.py": 1.0})


def test_a_record_reads_back_what_it_writes() -> None:
    back = full_run.parse(full_run.render(RUN))
    assert (back.commit, back.date, back.total_score) == (RUN.commit, RUN.date, 0.9912)
    assert back.scores == {"master/node.py": 0.9877, "slave_sim/pacing.py": 1.0}  # 4 decimals


@pytest.mark.parametrize(("change", "message"), [
    (lambda t: t.replace('date = "2026-12-06"\n', ""), "missing date"),
    (lambda t: 'why = "extra"\n' + t, "unknown key(s) why"),
    (lambda t: t.replace(RUN.commit, RUN.commit[:12]), "40 hex digits"),
    (lambda t: t.replace(RUN.commit, RUN.commit.upper()), "40 hex digits"),
    (lambda t: t.replace("2026-12-06", "6 Dec 2026"), "YYYY-MM-DD"),
    (lambda t: t.replace("= 1.0000", "= 1.5"), "slave_sim/pacing.py must be a score"),
    (lambda t: t.replace("total_score = 0.9912", "total_score = true"), "total_score must"),
    (lambda t: t.split("[scores]")[0] + "scores = 1\n", "scores must be a table"),
    (lambda t: t.replace('commit = "', 'commit = ""'), "last.toml: "),
])
def test_a_malformed_record_is_refused_saying_what_is_wrong(change, message: str) -> None:
    with pytest.raises(full_run.FullRunError) as caught:
        full_run.parse(change(full_run.render(RUN)), "last.toml")
    assert str(caught.value).startswith("last.toml: ")
    assert message in str(caught.value)


def test_no_record_file_is_no_full_run(tmp_path: Path) -> None:
    assert full_run.load(tmp_path / "absent.toml") is None


def test_the_shipped_record_loads_and_scores_configured_modules() -> None:
    run = full_run.load()
    assert run is not None
    configured = {c.path for c in modules.load(ROOT)}
    assert run.scores and set(run.scores) <= configured
    assert 0.9 < run.total_score <= 1.0
