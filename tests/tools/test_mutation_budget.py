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


STUCK_MODULE = ("def wait_for(ready: bool) -> int:\n    while not ready:\n        pass\n"
                "    return 0\n")
FAST_TEST = "import stuck\n\n\ndef test_ready() -> None:\n    assert stuck.wait_for(True) == 0\n"
SLOW_TEST = "import time\n\n\ndef test_slow() -> None:\n    time.sleep(2.0)\n"


def test_a_mutant_stuck_in_a_fast_file_ends_at_that_files_limit(tmp_path: Path) -> None:
    # Two of the three mutants never return from wait_for(True) (`while ready`, `while not not
    # ready`); the third returns 1. The run's whole limit is three times the baseline (the
    # slow file's 2 s and more) plus 20 s; the fast file's own, three times its ~0 s plus 1 s
    # here, ends each stuck mutant there, so the baseline and all three take less than one
    # whole limit.
    (tmp_path / "stuck.py").write_text(STUCK_MODULE)
    (tmp_path / "test_fast.py").write_text(FAST_TEST)
    (tmp_path / "test_slow.py").write_text(SLOW_TEST)
    job = runner.Job("stuck.py", "stuck", ["test_fast.py", "test_slow.py"])
    result = runner.score_module(tmp_path, job, [], jobs=2, file_allowance_s=1.0)
    assert result.tests == ["test_fast.py", "test_slow.py"]
    assert result.planned == 3 and result.killed == 3 and result.timed_out == 2
    assert result.limit_s > 26.0
    assert result.seconds < result.limit_s


def test_each_files_limit_is_three_baselines_plus_the_allowance() -> None:
    limits = runner.file_limits({"a.py": 2.0, "b.py": 0.5}, ["a.py", "b.py", "c.py"], 10.0)
    assert limits == {"a.py": 16.0, "b.py": 11.5, "c.py": 10.0}
