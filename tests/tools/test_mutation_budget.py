"""The CI mode's time box (tools/mutation/runner.py): a module whose unmutated tests are still
running when the box ends was not reached; it is reported incomplete, never as tests that fail
unmutated (which would fail the CI run for the box's timing, not for the code)."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from tools.mutation import runner

SLOW_TEST = '''
import time


def test_takes_longer_than_the_box() -> None:
    time.sleep(6.0)
'''


def _slow_job(tmp_path: Path) -> runner.Job:
    test = tmp_path / "test_slow_box.py"
    test.write_text(SLOW_TEST)
    return runner.Job("tools/mutation/runner.py", "tools.mutation.runner", [str(test)])


def test_a_baseline_cut_by_the_time_box_is_an_incomplete_module(tmp_path: Path) -> None:
    # 1.6 s left: the child's alarm rings after 1 whole second, before the deadline itself
    deadline = time.monotonic() + 1.6
    result = runner.score_module(Path.cwd(), _slow_job(tmp_path), [], deadline=deadline)
    assert result.complete is False
    assert result.planned == 0


def test_a_baseline_that_fails_outside_the_box_is_still_an_error(tmp_path: Path) -> None:
    test = tmp_path / "test_fails.py"
    test.write_text("def test_fails() -> None:\n    assert False\n")
    job = runner.Job("tools/mutation/runner.py", "tools.mutation.runner", [str(test)])
    with pytest.raises(runner.BaselineError, match="fail unmutated"):
        runner.score_module(Path.cwd(), job, [], deadline=time.monotonic() + 60.0)


TINY_MODULE = "def double(value: int) -> int:\n    return value * 2\n"
FIRST_TEST = "import tiny\n\n\ndef test_zero() -> None:\n    assert tiny.double(0) == 0\n"
SECOND_TEST = "import tiny\n\n\ndef test_three() -> None:\n    assert tiny.double(3) == 6\n"


def _tiny_job(root: Path, max_test_files: int | None) -> runner.Job:
    (root / "tiny.py").write_text(TINY_MODULE)
    (root / "test_first.py").write_text(FIRST_TEST)
    (root / "test_second.py").write_text(SECOND_TEST)
    return runner.Job("tiny.py", "tiny", ["test_first.py", "test_second.py"],
                      max_test_files=max_test_files)


def test_the_tests_a_mutant_runs_are_a_count_of_files_not_a_time(tmp_path: Path) -> None:
    # Only the second file tells value * 2 from its mutants. With every file chosen it runs
    # however long the first takes (a time cap once left it out on a slow machine, and the CI
    # run there found survivors that a fast machine killed); with one file chosen it never does.
    every_file = runner.score_module(tmp_path, _tiny_job(tmp_path, None), [])
    assert sorted(every_file.tests) == ["test_first.py", "test_second.py"]
    assert every_file.planned > 0 and every_file.survived == 0
    assert every_file.killed == every_file.planned
    first_only = runner.score_module(tmp_path, _tiny_job(tmp_path, 1), [])
    assert first_only.tests == ["test_first.py"]
    assert first_only.survived == first_only.planned > 0
