"""The CI mode's selection (``--changed-since``) in a throw-away git repository, and the
command line's ``--help``."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from tools.mutation import changed, cli
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
    two commits; the command line pointed at it."""
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
    return tmp_path


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


def test_the_default_base_is_head_1_without_a_remote_else_the_merge_base(repo: Path,
                                                                          capsys) -> None:
    first = git(repo, "rev-parse", "HEAD~1")
    assert changed.default_base(repo) == first
    (repo / "common/a.py").write_text("A = 5\n")
    git(repo, "commit", "-q", "-am", "three")
    assert selected(capsys, "--changed-since") == ["common/a.py"]  # HEAD~1: the last commit
    git(repo, "update-ref", "refs/remotes/origin/main", first)
    assert changed.default_base(repo) == first  # the branch left main at the first commit
    assert selected(capsys, "--changed-since") == ["common/a.py", "common/b.py"]
    assert changed.changed_files(repo, first) == {"common/a.py", "common/b.py"}


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


def test_only_a_completed_run_below_the_minimum_fails() -> None:
    results = {"low.py": ModuleResult(killed=9, survived=1),
               "ok.py": ModuleResult(killed=19, survived=1),
               "cut.py": ModuleResult(killed=1, survived=1, planned=10, complete=False),
               "late.py": None}
    assert cli.below_min_score(results, 0.95) == ["low.py"]
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
