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
