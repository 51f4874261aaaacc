"""Running the tests against the mutants: one forked child per mutant, nothing on disk.

A parent process imports the heavy libraries once (:data:`PRELOAD`) and forks one child per
mutant; the child serves the mutated source for the one module (an import hook, plus
``linecache`` so that Warp compiles the mutated kernel source) and runs pytest on the module's
tests with ``-x``. A mutant is *killed* when they fail (or crash, or exceed the time limit),
*survived* when they pass. Nothing is written into the source tree; Warp kernels compile into
a private cache the caller deletes.
"""

from __future__ import annotations

import json
import os
import signal
import sys
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

from .equivalents import Equivalent, reason_for
from .mutants import Mutant, mutants

#: Imported once in the parent, before forking (a child pays none of it).
PRELOAD = ("numpy", "scipy.linalg", "scipy.signal", "control", "msgpack", "zenoh", "warp",
           "hypothesis", "pytest", "mcap", "can", "canopen", "cantools", "matplotlib")
#: pytest plugins a mutant run does without (unraisableexception's gc.collect() alone costs
#: most of a second per run over the preloaded libraries).
PYTEST_PLUGINS_OFF = ("-p", "no:cacheprovider", "-p", "no:unraisableexception", "-p",
                      "no:threadexception", "-p", "no:benchmark", "-p", "no:junitxml", "-p",
                      "no:pastebin", "-p", "no:doctest")
#: The longest a baseline (the tests on the unmutated module) may take.
BASELINE_LIMIT_S = 600.0
#: A mutant's run may take three times its baseline plus this, s (the whole limit).
RUN_ALLOWANCE_S = 20.0
#: Each test file of a mutant's run may take three times its baseline time plus this, s:
#: room for a mutated Warp module's compile (seconds on the CPU, more on a loaded machine) in
#: whichever file launches it first. A mutant stuck in a fast file (a receive loop that
#: never returns) is ended there, not after the whole run's limit.
FILE_ALLOWANCE_S = 60.0

#: Children running now (pid -> mutant, None for a baseline), ended if the parent stops.
_RUNNING: dict[int, Mutant | None] = {}


class BaselineError(RuntimeError):
    """A module's tests do not pass on the unmutated module."""


@dataclass
class ModuleResult:
    """The outcome for one module. ``complete`` is False when the time budget ended the run
    before every mutant was tested (the counts are then those of the mutants tested)."""

    killed: int = 0
    survived: int = 0
    timed_out: int = 0
    equivalent: int = 0  # listed as equivalent: not run, not counted
    generated: int = 0  # all mutants of the module, before sampling
    planned: int = 0  # the mutants to run: sampled, less the equivalent ones
    seconds: float = 0.0
    limit_s: float = 0.0  # each mutant's run at most, s (its files have their own limits)
    complete: bool = True
    tests: list[str] = field(default_factory=list)  # in the order run, fastest first
    survivors: list[Mutant] = field(default_factory=list)

    @property
    def score(self) -> float:
        """killed / (killed + survived); 1.0 when nothing was tested."""
        total = self.killed + self.survived
        return self.killed / total if total else 1.0

    def as_dict(self) -> dict[str, object]:
        return {"killed": self.killed, "survived": self.survived, "score": round(self.score, 4),
                "timed_out": self.timed_out, "equivalent": self.equivalent,
                "generated": self.generated, "planned": self.planned,
                "complete": self.complete, "seconds": round(self.seconds, 1),
                "limit_s": round(self.limit_s, 1),
                "tests": self.tests}


def serve_mutant(name: str, path: Path, source: str) -> None:
    """In the child: import module ``name`` from ``source`` instead of its file (and let
    linecache, which inspect and Warp read kernel source through, return it too)."""
    import importlib.abc
    import importlib.util
    import linecache

    filename = str(path)
    linecache.cache[filename] = (len(source), None, source.splitlines(True), filename)

    class Loader(importlib.abc.Loader):
        def create_module(self, spec):  # noqa: ANN001, ANN202
            return None

        def exec_module(self, module):  # noqa: ANN001, ANN202
            module.__file__ = filename
            exec(compile(source, filename, "exec", dont_inherit=True), module.__dict__)

        def get_source(self, fullname):  # noqa: ANN001, ANN202
            return source

    class Finder(importlib.abc.MetaPathFinder):
        def find_spec(self, fullname, target_path=None, target=None):  # noqa: ANN001, ANN202
            if fullname != name:
                return None
            return importlib.util.spec_from_loader(name, Loader(), origin=filename)

    sys.meta_path.insert(0, Finder())


class _Baseline:
    """A pytest plugin for the baseline: each test file's time (setup, call and teardown),
    the files run to their end and whether a test failed. (No time cap: which tests a mutant
    runs must not depend on how fast the machine is, or a slow one would find survivors that
    a fast one kills.)"""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}
        self.completed: list[str] = []
        self.failed = False
        self._last: dict[str, str] = {}

    def pytest_collection_modifyitems(self, items) -> None:  # noqa: ANN001
        self._last = {item.nodeid.split("::")[0]: item.nodeid for item in items}

    def pytest_runtest_logreport(self, report) -> None:  # noqa: ANN001
        file = report.nodeid.split("::")[0]
        self.seconds[file] = self.seconds.get(file, 0.0) + report.duration
        self.failed |= report.failed

    def pytest_runtest_logfinish(self, nodeid: str, location: object) -> None:
        file = nodeid.split("::")[0]
        if self._last.get(file) == nodeid:
            self.completed.append(file)

    def verdict(self, code: int) -> int:
        """The child's exit status: 0 when every test run passed."""
        return 0 if code == 0 and not self.failed else 1


class _FileLimits:
    """A pytest plugin for a mutant's run: from each test file's first test on, the alarm
    rings after that file's own limit (``limits``, s; files not in it have none) or at the
    whole run's ``end`` (time.monotonic()), whichever comes first."""

    def __init__(self, limits: dict[str, float], end: float) -> None:
        self._limits = limits
        self._end = end
        self._file: str | None = None

    def pytest_runtest_logstart(self, nodeid: str, location: object) -> None:
        file = nodeid.split("::")[0]
        if file == self._file:
            return
        self._file = file
        seconds = self._end - time.monotonic()
        limit = self._limits.get(file)
        if limit is not None:
            seconds = min(seconds, limit)
        signal.setitimer(signal.ITIMER_REAL, max(seconds, 0.001))


def file_limits(seconds: dict[str, float], tests: list[str],
                allowance_s: float = FILE_ALLOWANCE_S) -> dict[str, float]:
    """Each of ``tests``' own limit in a mutant's run, s: three times its baseline
    ``seconds`` plus ``allowance_s``."""
    return {test: 3.0 * seconds.get(test, 0.0) + allowance_s for test in tests}


def _child(root: Path, tests: list[str], timeout_s: float, mutant: tuple[str, Mutant] | None,
           baseline_file: str | None = None, limits: dict[str, float] | None = None) -> None:
    """In a forked child: run ``tests`` (on ``mutant``: module name and mutant) and exit 0
    when they pass, within ``timeout_s`` in all and each file within its ``limits`` (s);
    for a baseline (``baseline_file``), write each file's seconds and the files run to their
    end there (JSON)."""
    status = 3
    try:
        end = time.monotonic() + timeout_s
        os.chdir(root)
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, 1)
        os.dup2(null, 2)
        for signum in (signal.SIGALRM, signal.SIGTERM, signal.SIGINT):
            signal.signal(signum, signal.SIG_DFL)
        signal.alarm(max(1, int(timeout_s)))
        if mutant is not None:
            serve_mutant(mutant[0], root / mutant[1].path, mutant[1].source)
        from hypothesis import HealthCheck
        from hypothesis import settings as hypothesis_settings

        # The same examples for every mutant and the baseline, no shared example database,
        # and no health check that a loaded machine fails (that would count as a kill).
        hypothesis_settings.register_profile(
            "mutation", derandomize=True, database=None, deadline=None,
            suppress_health_check=list(HealthCheck))
        hypothesis_settings.load_profile("mutation")
        import pytest

        plugin = _Baseline()
        plugins: list[object] = [plugin]
        if limits:
            plugins.append(_FileLimits(limits, end))
        code = pytest.main(["-x", "-q", "--no-header", *PYTEST_PLUGINS_OFF,
                            *(str(root / t) for t in tests)], plugins=plugins)
        if baseline_file is not None:
            Path(baseline_file).write_text(json.dumps(
                {"seconds": plugin.seconds, "completed": plugin.completed}))
        status = plugin.verdict(int(code))
    finally:
        sys.stdout.flush()
        os._exit(status)


def _outcome(status: int) -> str:
    """``passed``, ``failed`` or ``timeout`` from a child's wait status."""
    if os.WIFSIGNALED(status):
        return "timeout" if os.WTERMSIG(status) == signal.SIGALRM else "failed"
    return "passed" if os.WEXITSTATUS(status) == 0 else "failed"


def baseline(root: Path, tests: list[str],
             timeout_s: float) -> tuple[str, dict[str, float], list[str]]:
    """Run ``tests`` unmutated, in their order: the outcome, each test file's seconds and the
    files run to their end."""
    with tempfile.NamedTemporaryFile(suffix=".json") as handle:
        pid = os.fork()
        if pid == 0:
            _child(root, tests, timeout_s, None, handle.name)
        _RUNNING[pid] = None
        _, status = os.waitpid(pid, 0)
        del _RUNNING[pid]
        data = json.loads(Path(handle.name).read_text() or "{}")
    seconds = {file: float(s) for file, s in data.get("seconds", {}).items()}
    return _outcome(status), seconds, list(data.get("completed", []))


def run_mutants(root: Path, name: str, tests: list[str], timeout_s: float,
                found: list[Mutant], jobs: int, deadline: float | None = None,
                limits: dict[str, float] | None = None) -> Iterator[tuple[Mutant, str]]:
    """Yield (mutant, outcome) for each of ``found`` (module ``name``), ``jobs`` children at a
    time, each within ``timeout_s`` and each test file within its ``limits`` (s); past
    ``deadline`` (time.monotonic()) none is started and the running ones are ended without
    an outcome."""
    if not tests:
        raise ValueError("no tests to run the mutants against")
    pending = list(reversed(found))
    while pending or _RUNNING:
        if deadline is not None and time.monotonic() >= deadline:
            end_children()
            return
        while pending and len(_RUNNING) < jobs:
            mutant = pending.pop()
            pid = os.fork()
            if pid == 0:
                _child(root, tests, timeout_s, (name, mutant), limits=limits)
            _RUNNING[pid] = mutant
        pid, status = os.waitpid(-1, os.WNOHANG)
        if pid == 0:
            time.sleep(0.02)
            continue
        mutant = _RUNNING.pop(pid, None)
        if mutant is not None:
            yield mutant, _outcome(status)


def end_children() -> None:
    """Kill and reap every child still running."""
    for pid in list(_RUNNING):
        try:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
        except (ProcessLookupError, ChildProcessError):
            pass
        _RUNNING.pop(pid, None)


def preload(cache_dir: str) -> None:
    """Import :data:`PRELOAD` (those installed) and set Warp to compile into ``cache_dir``;
    SystemExit if that imported a ``haptic`` module (a child must import each afresh)."""
    import importlib

    for module in PRELOAD:
        try:
            importlib.import_module(module)
        except ImportError:
            pass
    import warp as wp

    wp.config.log_level = wp.LOG_WARNING
    wp.config.kernel_cache_dir = cache_dir
    wp.config.enable_backward = False  # no kernel here is differentiated: half the compile
    wp.init()
    import gc

    gc.collect()
    gc.freeze()  # the children's collections skip the preloaded heap
    loaded = [m for m in sys.modules if m == "haptic" or m.startswith("haptic.")]
    if loaded:
        raise SystemExit(f"mutation: preloading imported {loaded}")


@dataclass
class Job:
    """What to score: a module, the name it is imported by, its tests (the likeliest to catch
    its mutants first), its sampling, and how many of its test files, the first ones, are
    run (None: every one)."""

    path: str
    name: str
    tests: list[str]
    every: int = 1
    max_test_files: int | None = None

    def chosen_tests(self) -> list[str]:
        """The test files the baseline and the mutants run."""
        return self.tests[:self.max_test_files]


def _planned(root: Path, job: Job, result: ModuleResult, everything: bool,
             equivalents: list[Equivalent]) -> list[Mutant]:
    """The module's mutants to run (sampled unless ``everything``, less the equivalent)."""
    found = mutants(root, job.path)
    result.generated = len(found)
    if not everything and job.every > 1:
        found = found[::job.every]
    runnable = [m for m in found if reason_for(m, equivalents) is None]
    result.equivalent = len(found) - len(runnable)
    result.planned = len(runnable)
    return runnable


def score_module(root: Path, job: Job, equivalents: list[Equivalent], *, jobs: int = 1,
                 everything: bool = False, progress: bool = False,
                 deadline: float | None = None,
                 file_allowance_s: float = FILE_ALLOWANCE_S) -> ModuleResult:
    """Baseline (the job's chosen tests must pass unmutated: BaselineError otherwise; its time
    sets each mutant's limit, and its per-file times the order, fastest first, and each
    file's own limit, :func:`file_limits` with ``file_allowance_s``), then the mutants. Past
    ``deadline`` the result is returned incomplete."""
    result = ModuleResult()
    start = time.monotonic()
    limit = BASELINE_LIMIT_S if deadline is None else max(1.0, min(BASELINE_LIMIT_S,
                                                                   deadline - start))
    # a baseline ended by what was left of the budget did not fail: its module was not reached
    # (the child's alarm counts whole seconds, so it may ring just before the deadline)
    cut_by_budget = limit < BASELINE_LIMIT_S
    chosen = job.chosen_tests()
    outcome, seconds, completed = baseline(root, chosen, limit)
    baseline_s = time.monotonic() - start
    if outcome != "passed":
        if outcome == "timeout" and cut_by_budget:
            result.complete, result.seconds = False, baseline_s
            return result
        raise BaselineError(f"the tests of {job.path} fail unmutated ({outcome}); run: "
                            f"python3 -m pytest -x {' '.join(chosen)}")
    if not completed:
        raise BaselineError(f"no test file of {job.path} ran to its end: {chosen}")
    result.tests = sorted(completed, key=lambda t: (seconds.get(t, 0.0), t))
    if progress:
        left = len(job.tests) - len(chosen)
        print(f"  baseline: {len(completed)} test file(s) pass in {baseline_s:.1f} s"
              f"{f' ({left} more left out by max_test_files)' if left else ''}; fastest first: "
              f"{', '.join(result.tests)}", file=sys.stderr, flush=True)
    # A mutated Warp kernel compiles first; a mutant much slower than the baseline is stuck
    # (an endless loop, say) and counts as killed.
    timeout_s = result.limit_s = 3.0 * baseline_s + RUN_ALLOWANCE_S
    limits = file_limits(seconds, result.tests, file_allowance_s)
    runnable = _planned(root, job, result, everything, equivalents)
    original = (root / job.path).read_text()
    mark = {"passed": "SURVIVED", "failed": "killed", "timeout": "killed (timeout)"}
    for number, (mutant, outcome) in enumerate(run_mutants(
            root, job.name, result.tests, timeout_s, runnable, jobs, deadline, limits), 1):
        if outcome == "passed":
            result.survived += 1
            result.survivors.append(mutant)
        else:
            result.killed += 1
            result.timed_out += outcome == "timeout"
        if progress:
            print(f"  [{number}/{len(runnable)}] {job.path}:{mutant.line} {mutant.operator}: "
                  f"{mark[outcome]}", file=sys.stderr, flush=True)
            if outcome == "passed":
                print(mutant.diff(original), file=sys.stderr, flush=True)
    result.complete = result.killed + result.survived == len(runnable)
    result.survivors.sort(key=lambda m: m.line)
    result.seconds = time.monotonic() - start
    return result
