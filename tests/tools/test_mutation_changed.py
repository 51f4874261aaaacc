"""The CI mode's selection (``--changed-since``) in a throw-away git repository: each module's
change since its own last complete run, the newest first, and nothing to do when no configured
module changed; the records ``--record`` writes; the exit decision; the command line's
``--help``."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from tools.mutation import changed, cli, last_scores
from tools.mutation.runner import ModuleResult

ROOT = Path(__file__).resolve().parents[2]


def git(root: Path, *args: str) -> str:
    done = subprocess.run(["git", "-C", str(root), "-c", "user.name=t", "-c",
                           "user.email=t@example.invalid", "-c", "commit.gpgsign=false",
                           *args], capture_output=True, text=True, check=True)
    return done.stdout.strip()


@pytest.fixture
def repo(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A repository with two configured modules, a test of each (one imports lazily) and
    two commits, no module's run recorded; the command line pointed at it."""
    files = {
        "pyproject.toml": '[tool.setuptools.package-dir]\n"haptic.common" = "common"\n',
        "common/__init__.py": "",
        "common/a.py": "A = 1\n",
        "common/b.py": "B = 2\n",
        "tests/test_a.py": "def test_a():\n    from haptic.common.a import A\n    assert A\n",
        "tests/test_b.py": "from haptic.common import b\n",
        "modules.toml": 'modules = ["common/a.py", "common/b.py"]\n',
        "equivalents.toml": "",
    }
    for path, text in files.items():
        (tmp_path / path).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / path).write_text(text)
    git(tmp_path, "init", "-q", "-b", "work")
    git(tmp_path, "add", "-A")
    git(tmp_path, "commit", "-q", "-m", "one")
    (tmp_path / "common/b.py").write_text("B = 4\n")
    git(tmp_path, "commit", "-q", "-am", "two")
    monkeypatch.setattr(cli, "ROOT", tmp_path)
    monkeypatch.setattr(cli, "MODULES_FILE", tmp_path / "modules.toml")
    monkeypatch.setattr(cli, "EQUIVALENTS_FILE", tmp_path / "equivalents.toml")
    monkeypatch.setattr(cli, "SCORES_FILE", tmp_path / "last_scores.toml")
    return tmp_path


def record(root: Path, commit: str, scored: tuple[str, ...] = ("common/a.py", "common/b.py"),
           score: float = 1.0) -> None:
    """Record a complete run of ``scored`` at ``commit`` (untracked here, so that writing it
    is no change of a tracked file), keeping the other modules' records."""
    path = root / "last_scores.toml"
    records = last_scores.load(path) | {
        module: last_scores.Scored(commit, "2026-12-01", score) for module in scored}
    path.write_text(last_scores.render(records))


def selected(capsys: pytest.CaptureFixture[str], *args: str) -> list[str]:
    """The modules ``--changed-since`` picks (``--tests``: nothing is run)."""
    assert cli.main(["--tests", "--json", *args]) == 0
    out, err = capsys.readouterr()
    found = list(json.loads(out))
    assert f"{len(found)} configured module(s) touched: {', '.join(found) or 'none'}" in err
    return found


def test_only_the_touched_modules_are_selected(repo: Path, capsys) -> None:
    base = git(repo, "rev-parse", "HEAD")
    assert selected(capsys, "--changed-since", base) == []
    (repo / "common/b.py").write_text("B = 3\n")  # uncommitted: still a change since base
    assert selected(capsys, "--changed-since", base) == ["common/b.py"]
    git(repo, "add", "-A")
    git(repo, "commit", "-q", "-m", "three")
    assert selected(capsys, "--changed-since", base) == ["common/b.py"]


def test_a_changed_test_selects_the_module_it_imports_lazily(repo: Path, capsys) -> None:
    base = git(repo, "rev-parse", "HEAD")
    (repo / "tests/test_a.py").write_text("def test_a():\n    from haptic.common.a import A\n")
    assert selected(capsys, "--changed-since", base) == ["common/a.py"]
    assert selected(capsys, "--changed-since", base, "--module", "common/b.py") == []


def test_the_default_change_is_since_each_modules_last_run(repo: Path, capsys) -> None:
    first = git(repo, "rev-parse", "HEAD~1")
    record(repo, first)
    assert changed.default_base(repo, first) == first
    assert selected(capsys, "--changed-since") == ["common/b.py"]  # "two" changed it
    (repo / "common/a.py").write_text("A = 5\n")
    git(repo, "commit", "-q", "-am", "three")
    assert selected(capsys, "--changed-since") == ["common/a.py", "common/b.py"]
    assert changed.changed_files(repo, first) == {"common/a.py", "common/b.py"}
    record(repo, git(repo, "rev-parse", "HEAD"))  # both scored at HEAD: nothing changed since
    assert selected(capsys, "--changed-since") == []


def test_each_module_counts_from_its_own_record(repo: Path, capsys) -> None:
    record(repo, git(repo, "rev-parse", "HEAD~1"), scored=("common/a.py",))
    record(repo, git(repo, "rev-parse", "HEAD"), scored=("common/b.py",))
    assert selected(capsys, "--changed-since") == []  # b changed in "two", then was scored
    (repo / "common/a.py").write_text("A = 5\n")
    git(repo, "commit", "-q", "-am", "three")
    assert selected(capsys, "--changed-since") == ["common/a.py"]
    record(repo, git(repo, "rev-parse", "HEAD"), scored=("common/a.py",))
    assert selected(capsys, "--changed-since") == []


def test_a_record_below_the_minimum_counts_as_changed(repo: Path, capsys) -> None:
    head = git(repo, "rev-parse", "HEAD")
    record(repo, head, scored=("common/a.py",), score=0.9)
    record(repo, head, scored=("common/b.py",), score=0.96)
    assert cli.main(["--tests", "--json", "--changed-since"]) == 0
    out, err = capsys.readouterr()
    assert list(json.loads(out)) == ["common/a.py"]
    assert "0 with no record and 1 below 95.0 % count as changed" in err
    assert selected(capsys, "--changed-since", "--min-score", "0.97") == [
        "common/b.py", "common/a.py"]
    assert selected(capsys, "--changed-since", "--min-score", "0.8") == []


def test_the_newest_change_runs_first(repo: Path, capsys) -> None:
    record(repo, git(repo, "rev-parse", "HEAD~1"))
    (repo / "common/a.py").write_text("A = 5\n")
    git(repo, "commit", "-q", "-am", "three: a after b")
    assert selected(capsys, "--changed-since") == ["common/a.py", "common/b.py"]
    (repo / "common/b.py").write_text("B = 6\n")
    git(repo, "commit", "-q", "-am", "four: b again")
    assert selected(capsys, "--changed-since") == ["common/b.py", "common/a.py"]
    (repo / "tests/test_a.py").write_text("def test_a():\n    from haptic.common.a import A\n")
    assert selected(capsys, "--changed-since") == ["common/a.py", "common/b.py"]  # uncommitted
    rank = changed.recency(repo, git(repo, "rev-parse", "HEAD~2"))
    assert rank == {"tests/test_a.py": 0, "common/b.py": 1, "common/a.py": 2}


def test_a_module_with_no_record_counts_as_changed(repo: Path, capsys) -> None:
    assert selected(capsys, "--changed-since") == ["common/b.py", "common/a.py"]  # no record
    record(repo, git(repo, "rev-parse", "HEAD"), scored=("common/b.py",))
    assert selected(capsys, "--changed-since") == ["common/a.py"]
    assert selected(capsys, "--changed-since", "HEAD") == []  # an explicit REF: the diff only


def test_without_the_recorded_commit_the_change_is_the_last_commit(repo: Path,
                                                                    capsys) -> None:
    record(repo, "0" * 40)  # a commit this clone lacks
    assert changed.default_base(repo, "0" * 40) == git(repo, "rev-parse", "HEAD~1")
    assert selected(capsys, "--changed-since") == ["common/b.py"]
    git(repo, "checkout", "-q", "-b", "side", "HEAD~1")  # a commit off HEAD's history
    (repo / "common/a.py").write_text("A = 7\n")
    git(repo, "commit", "-q", "-am", "side")
    side = git(repo, "rev-parse", "HEAD")
    git(repo, "checkout", "-q", "work")
    record(repo, side)
    assert changed.default_base(repo, side) == git(repo, "rev-parse", "HEAD~1")
    assert selected(capsys, "--changed-since") == ["common/b.py"]


def test_no_configured_module_changed_exits_0_running_nothing(repo: Path, capsys) -> None:
    record(repo, git(repo, "rev-parse", "HEAD"))
    (repo / "README").write_text("not a module\n")
    git(repo, "add", "README")
    git(repo, "commit", "-q", "-m", "docs only")
    assert cli.main(["--changed-since", "--time-budget-s", "300", "--min-score", "0.95"]) == 0
    err = capsys.readouterr().err
    assert "(2 recorded; 0 with no record and 0 below 95.0 % count as changed): 0 " \
        "configured module(s) touched: none" in err
    assert "0 module(s), 0 mutants tested" in err


def test_record_takes_the_configured_settings_on_a_clean_tree(repo: Path, capsys) -> None:
    for args in (["--max-test-files", "1"], ["--tests"], ["--count"]):
        with pytest.raises(SystemExit) as caught:
            cli.main(["--record", *args])
        assert caught.value.code == 2
        assert "--record: records a run with modules.toml's settings" in \
            capsys.readouterr().err
    (repo / "common/a.py").write_text("A = 8\n")
    with pytest.raises(SystemExit) as caught:
        cli.main(["--record", "--module", "common/b.py"])
    assert caught.value.code == 2
    assert "--record: uncommitted changes (common/a.py)" in capsys.readouterr().err


def test_record_writes_the_completed_modules_and_keeps_the_others(repo: Path, capsys) -> None:
    old = git(repo, "rev-parse", "HEAD~1")
    record(repo, old, scored=("common/a.py", "common/b.py"), score=0.99)
    results = {"common/b.py": ModuleResult(killed=19, survived=1),
               "common/a.py": ModuleResult(killed=3, survived=0, planned=9, complete=False)}
    cli._record(results, ["common/a.py", "common/b.py"])
    records = last_scores.load(repo / "last_scores.toml")
    assert list(records) == ["common/a.py", "common/b.py"]
    assert records["common/a.py"] == last_scores.Scored(old, "2026-12-01", 0.99)  # cut short
    assert records["common/b.py"].commit == git(repo, "rev-parse", "HEAD")
    assert records["common/b.py"].score == 0.95
    err = capsys.readouterr().err
    assert "1 module(s) recorded" in err
    assert "1 module(s) not recorded (their run did not complete): common/a.py" in err


def test_without_a_parent_the_whole_tree_is_the_change(tmp_path: Path) -> None:
    (tmp_path / "a.py").write_text("A = 1\n")
    git(tmp_path, "init", "-q")
    git(tmp_path, "add", "-A")
    git(tmp_path, "commit", "-q", "-m", "first")
    assert changed.changed_files(tmp_path, changed.default_base(tmp_path)) == {"a.py"}


def test_an_unknown_ref_is_a_usage_error(repo: Path, capsys) -> None:
    with pytest.raises(SystemExit) as caught:
        cli.main(["--changed-since", "no-such-ref", "--tests"])
    assert caught.value.code == 2
    assert "no-such-ref" in capsys.readouterr().err


def test_a_completed_run_below_the_minimum_fails_and_a_cut_one_once_it_cannot_reach_it(
        ) -> None:
    results = {"low.py": ModuleResult(killed=9, survived=1),
               "ok.py": ModuleResult(killed=19, survived=1),
               "cut.py": ModuleResult(killed=1, survived=1, planned=100, complete=False),
               "doomed.py": ModuleResult(killed=1, survived=6, planned=100, complete=False),
               "late.py": None}
    assert cli.best_score(results["cut.py"]) == 0.99
    assert cli.best_score(results["doomed.py"]) == 0.94
    assert cli.best_score(results["low.py"]) == 0.9
    assert cli.below_min_score(results, 0.95) == ["low.py", "doomed.py"]
    assert cli.below_min_score(results, 0.9) == []


@pytest.mark.parametrize("command", [["tools/mutation/run.py"], ["-m", "tools.mutation"]])
def test_the_command_line_help_works(command: list[str]) -> None:
    done = subprocess.run([sys.executable, *command, "--help"], capture_output=True, text=True,
                          cwd=ROOT, timeout=60, check=False)
    assert done.returncode == 0, done.stderr
    for option in ("--changed-since", "--time-budget-s", "--min-score", "--module"):
        assert option in done.stdout


def test_the_command_line_takes_no_abbreviations(capsys) -> None:
    with pytest.raises(SystemExit) as caught:
        cli.build_parser().parse_args(["--changed", "HEAD"])
    assert caught.value.code == 2
    assert "--changed" in capsys.readouterr().err
