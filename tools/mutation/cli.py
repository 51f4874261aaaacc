"""The command line: score the configured modules, or those a change touched (CI mode).

Exit status: 0 when every module whose run completed scores at least ``--min-score``; 1 when
one scores below it, or a module the time budget cut short has more survivors already than the
minimum allows; 2 for a usage error or a module whose tests fail unmutated; 130 when stopped.
A module the time budget did not reach is reported as not run and fails nothing.
"""

from __future__ import annotations

import argparse
import datetime
import json
import shutil
import signal
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from . import changed, equivalents, finder, last_scores, modules, runner
from .runner import BaselineError, Job, ModuleResult

ROOT = Path(__file__).resolve().parents[2]
PROGRAM = "python3 tools/mutation/run.py"
DEFAULT_MIN_SCORE = 0.95
#: The data files: the configured modules, the equivalent mutants, each module's last run.
MODULES_FILE = modules.DEFAULT_PATH
EQUIVALENTS_FILE = equivalents.DEFAULT_PATH
SCORES_FILE = last_scores.DEFAULT_PATH
#: module path -> its test files (the test-finder, memoised).
TestsOf = Callable[[str], list[str]]


def build_parser() -> argparse.ArgumentParser:
    """The parser of the command line (its options are the documented ones)."""
    parser = argparse.ArgumentParser(
        prog=PROGRAM, allow_abbrev=False, description="Mutation score of the configured modules "
        "(tools/mutation/modules.toml): how many small planted bugs their tests catch.")
    parser.add_argument("--module", action="append", metavar="PATH",
                        help="a configured module to mutate (repeatable; default: all)")
    parser.add_argument("--changed-since", nargs="?", const="", default=None, metavar="REF",
                        help="only the configured modules the change since REF touched (the "
                        "module or one of its tests), the newest change first; without REF, "
                        "each module's change since its own last complete run "
                        "(tools/mutation/last_scores.toml; the last commit when the clone "
                        "lacks that commit), and the modules with no record or one below "
                        "--min-score")
    parser.add_argument("--time-budget-s", type=float, default=None, metavar="S",
                        help="stop S seconds after the start: modules not reached are reported "
                        "as not run, a module cut short as unfinished (it fails only when its "
                        "survivors so far already put it below --min-score)")
    parser.add_argument("--min-score", type=float, default=DEFAULT_MIN_SCORE, metavar="X",
                        help="exit 1 when a module whose run completed scores below X "
                        f"(default {DEFAULT_MIN_SCORE})")
    parser.add_argument("--record", action="store_true",
                        help="on a tree with no uncommitted change, write the commit, date and "
                        "score of each module whose run completed to "
                        "tools/mutation/last_scores.toml (the others keep theirs)")
    parser.add_argument("--max-test-files", type=int, default=None, metavar="N",
                        help="run the first N of a module's test files, the likeliest to "
                        "catch its mutants first (default: modules.toml's max_test_files; "
                        "0: all of them)")
    parser.add_argument("--json", action="store_true", help="print JSON on stdout")
    parser.add_argument("--all", action="store_true",
                        help="every mutant, also of the sampled modules (the kernels)")
    parser.add_argument("--jobs", type=int, default=1, metavar="N",
                        help="mutants tested at once (default 1; one per free core)")
    parser.add_argument("--survivors", action="store_true",
                        help="print each surviving mutant's diff (stderr)")
    parser.add_argument("--count", action="store_true",
                        help="only count the mutants per module, run nothing")
    parser.add_argument("--tests", action="store_true",
                        help="only list each module's tests (found from their imports), "
                        "run nothing")
    parser.add_argument("--equivalents", action="store_true",
                        help="print the table of equivalent mutants (Markdown), run nothing")
    parser.add_argument("--progress", action="store_true", help="one line per mutant on stderr")
    return parser


def _tests_of(graph: finder.ImportGraph, depth: dict[str, int]) -> TestsOf:
    """A memo of the test-finder: module path -> its test files at the module's ``depth``,
    the likeliest to catch its mutants first."""
    memo: dict[str, list[str]] = {}

    def tests_of(path: str) -> list[str]:
        if path not in memo:
            found = finder.tests_for(path, graph, depth.get(path, 1))
            memo[path] = finder.ordered(path, found, graph)
        return memo[path]

    return tests_of


def _select(args: argparse.Namespace, configured: list[str], tests_of: TestsOf) -> list[str]:
    """The modules to run: ``--module``'s, the touched ones (the newest change first), or
    all; SystemExit(2) on a usage error."""
    if args.changed_since is None:
        return args.module or configured
    candidates = args.module or configured
    try:
        if args.changed_since:
            paths, rank, since = _touched_since(args.changed_since, candidates, tests_of)
        else:
            paths, rank, since = _touched_since_records(candidates, tests_of, args.min_score)
    except (changed.GitError, last_scores.RecordError) as error:
        print(f"mutation: --changed-since: {error}", file=sys.stderr)
        raise SystemExit(2) from None
    paths = changed.newest_first(paths, rank, tests_of)
    print(f"mutation: {since}: {len(paths)} configured module(s) touched: "
          f"{', '.join(paths) or 'none'}", file=sys.stderr, flush=True)
    return paths


def _touched_since(ref: str, candidates: list[str],
                   tests_of: TestsOf) -> tuple[list[str], dict[str, int], str]:
    """The ``candidates`` the change since ``ref`` touched, the files' recency and a line
    saying what the change was."""
    files = changed.changed_files(ROOT, ref)
    rank = changed.recency(ROOT, ref) if files else {}
    return (changed.touched(candidates, files, _tests_if_changed(files, tests_of)), rank,
            f"changed since {ref[:12]}: {len(files)} file(s)")


def _touched_since_records(candidates: list[str], tests_of: TestsOf,
                           min_score: float) -> tuple[list[str], dict[str, int], str]:
    """The ``candidates`` changed since their own last complete run (last_scores.toml), those
    with no record and those whose record is below ``min_score``; the files' recency over
    HEAD's whole history; and a line saying so."""
    records = last_scores.load(SCORES_FILE)
    bases: dict[str, str] = {}  # recorded commit -> the base its change is measured from
    files_since: dict[str, set[str]] = {}  # base -> the files changed since
    paths, unscored, low, fallback = [], [], [], []
    for path in candidates:
        record = records.get(path)
        if record is None or record.score < min_score:
            (unscored if record is None else low).append(path)
            paths.append(path)
            continue
        if record.commit not in bases:
            bases[record.commit] = changed.default_base(ROOT, record.commit)
        base = bases[record.commit]
        if base != record.commit:
            fallback.append(path)
        if base not in files_since:
            files_since[base] = changed.changed_files(ROOT, base)
        files = files_since[base]
        if changed.touched([path], files, _tests_if_changed(files, tests_of)):
            paths.append(path)
    rank = changed.recency(ROOT, changed.EMPTY_TREE)
    since = (f"changed since each module's last complete run ({len(records)} recorded; "
             f"{len(unscored)} with no record and {len(low)} below "
             f"{min_score * 100:.1f} % count as changed")
    if fallback:
        since += f"; {len(fallback)} recorded at a commit not in this history: the last commit"
    return paths, rank, since + ")"


def _tests_if_changed(files: set[str], tests_of: TestsOf) -> TestsOf:
    """``tests_of``, or no tests when no test file changed (the finder need not run)."""
    if any(f.startswith(finder.TESTS_DIR + "/") for f in files):
        return tests_of
    return lambda _path: []


def _line(path: str, result: ModuleResult) -> str:
    """One module's outcome, one line."""
    tested = result.killed + result.survived
    if not result.complete and not tested:
        return f"mutation: {path}: unfinished (time budget), nothing tested"
    state = "" if result.complete else f", unfinished ({tested} of {result.planned} tested)"
    return (f"mutation: {path}: {result.killed} killed, {result.survived} survived "
            f"({result.score * 100:.1f} %), {result.equivalent} equivalent, "
            f"{result.seconds:.0f} s{state}")


def _run(args: argparse.Namespace, paths: list[str], configured: dict[str, modules.Configured],
         tests_of: TestsOf, entries: list[equivalents.Equivalent],
         deadline: float | None) -> dict[str, ModuleResult | None]:
    """Score each of ``paths`` in turn until ``deadline`` (time.monotonic(); None: all), None
    for one not reached."""
    package_dir = finder.package_dirs(ROOT)
    results: dict[str, ModuleResult | None] = {}
    for path in paths:
        if deadline is not None and time.monotonic() >= deadline:
            results[path] = None
            print(f"mutation: {path}: not run (time budget)", file=sys.stderr, flush=True)
            continue
        settings = configured[path]
        job = Job(path, finder.module_name(path, package_dir), tests_of(path), settings.every,
                  settings.max_test_files if args.max_test_files is None
                  else args.max_test_files or None)
        if not job.tests:
            raise BaselineError(f"no test imports {path} (nor a module that imports it)")
        results[path] = result = runner.score_module(
            ROOT, job, entries, jobs=args.jobs, everything=args.all, progress=args.progress,
            deadline=deadline)
        print(_line(path, result), file=sys.stderr, flush=True)
    return results


def _report(args: argparse.Namespace, results: dict[str, ModuleResult | None],
            elapsed_s: float) -> None:
    """The table (or JSON) on stdout, the survivors' diffs on stderr with ``--survivors``."""
    done = {p: r for p, r in results.items() if r is not None}
    killed = sum(r.killed for r in done.values())
    total = killed + sum(r.survived for r in done.values())
    total_score = killed / total if total else 1.0
    if args.json:
        print(json.dumps({"modules": {p: (r.as_dict() if r else None)
                                      for p, r in results.items()},
                          "total_score": round(total_score, 4), "seconds": round(elapsed_s, 1),
                          "jobs": args.jobs, "sampled": not args.all}, indent=2))
    else:
        print(f"{'module':34s} {'killed':>7s} {'survived':>9s} {'score':>7s} {'equiv.':>7s} "
              f"{'of':>5s} {'time':>6s}")
        for path, r in results.items():
            if r is None or not (r.complete or r.killed + r.survived):
                print(f"{path:34s} {'not run' if r is None else 'unfinished'} (time budget)")
                continue
            print(f"{path:34s} {r.killed:7d} {r.survived:9d} {r.score * 100:6.1f}% "
                  f"{r.equivalent:7d} {r.generated:5d} {r.seconds:5.0f}s"
                  f"{'' if r.complete else '  unfinished'}")
        print(f"{'total':34s} {killed:7d} {total - killed:9d} {total_score * 100:6.1f}% "
              f"{'':13s} {elapsed_s:5.0f}s")
    if args.survivors:
        for path, r in done.items():
            original = (ROOT / path).read_text()
            for mutant in r.survivors:
                print(f"--- survivor {path}:{mutant.line} {mutant.operator}", file=sys.stderr)
                print(mutant.diff(original), file=sys.stderr)


def best_score(result: ModuleResult) -> float:
    """The highest score ``result`` can end with: its score when complete; for a run cut
    short, the score it would have if every mutant not tested were killed."""
    if result.complete or not result.planned:
        return result.score
    return (result.planned - result.survived) / result.planned


def below_min_score(results: dict[str, ModuleResult | None], min_score: float) -> list[str]:
    """The modules that score below ``min_score``: a completed run's score, or a run cut
    short whose survivors so far already keep it below (a module not run is none of them)."""
    return [p for p, r in results.items() if r is not None and best_score(r) < min_score]


def _stop(signum: int, _frame: object) -> None:
    raise KeyboardInterrupt(f"signal {signum}")


def _inspect(args: argparse.Namespace, paths: list[str], tests_of: TestsOf,
             entries: list[equivalents.Equivalent]) -> None:
    """``--equivalents``, ``--count`` or ``--tests``: print, run nothing."""
    from .mutants import mutants

    if args.equivalents:
        print(equivalents.markdown_table(entries))
    elif args.count:
        counts = {path: len(mutants(ROOT, path)) for path in paths}
        print(json.dumps(counts) if args.json else "\n".join(f"{n:5d}  {p}"
                                                             for p, n in counts.items()))
    else:
        found = {path: tests_of(path) for path in paths}
        print(json.dumps(found, indent=2) if args.json else "\n".join(
            f"{p}:\n" + "".join(f"    {t}\n" for t in tests) for p, tests in found.items()))


def main(argv: list[str] | None = None) -> int:
    """Run the command line; the exit status (see the module's docstring)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    started = time.monotonic()
    if args.jobs < 1:
        parser.error("--jobs must be at least 1")
    if args.max_test_files is not None and args.max_test_files < 0:
        parser.error("--max-test-files must be at least 0 (0: every test file)")
    if args.record and (args.max_test_files is not None or args.equivalents or args.count
                        or args.tests):
        parser.error("--record: records a run with modules.toml's settings: not with "
                     "--max-test-files, --equivalents, --count or --tests")
    try:
        configured = modules.load(ROOT, MODULES_FILE)
        entries = equivalents.load(EQUIVALENTS_FILE, frozenset(c.path for c in configured))
    except (modules.ModulesError, equivalents.EquivalentsError) as error:
        parser.error(str(error))
    by_path = {c.path: c for c in configured}
    for path in args.module or ():
        if path not in by_path:
            parser.error(f"--module {path}: not configured (tools/mutation/modules.toml)")
    if args.record and (dirty := [f for f in changed.uncommitted(ROOT)
                                  if ROOT / f != SCORES_FILE]):
        parser.error(f"--record: uncommitted changes ({', '.join(dirty[:5])}"
                     f"{', ...' if len(dirty) > 5 else ''}): a record names a commit")
    tests_of = _tests_of(finder.ImportGraph(ROOT), {c.path: c.depth for c in configured})
    paths = _select(args, list(by_path), tests_of)
    if args.equivalents or args.count or args.tests:
        _inspect(args, paths, tests_of, entries)
        return 0
    deadline = None if args.time_budget_s is None else started + args.time_budget_s
    return _score(args, paths, by_path, tests_of, entries, deadline)


def _score(args: argparse.Namespace, paths: list[str], configured: dict[str, modules.Configured],
           tests_of: TestsOf, entries: list[equivalents.Equivalent],
           deadline: float | None) -> int:
    """Preload, score ``paths`` until ``deadline``, report (and record the completed modules with
    ``--record``); the exit status."""
    start = time.monotonic()
    cache_dir = tempfile.mkdtemp(prefix="mutation-warp-cache-")
    signal.signal(signal.SIGTERM, _stop)
    try:
        if paths:
            runner.preload(cache_dir)
        results = _run(args, paths, configured, tests_of, entries, deadline)
    except KeyboardInterrupt:
        print("mutation: stopped", file=sys.stderr)
        return 130
    except BaselineError as error:
        print(f"mutation: {error}", file=sys.stderr)
        return 2
    finally:
        runner.end_children()
        shutil.rmtree(cache_dir, ignore_errors=True)
    elapsed_s = time.monotonic() - start
    _report(args, results, elapsed_s)
    below = below_min_score(results, args.min_score)
    tested = sum(r.killed + r.survived for r in results.values() if r is not None)
    print(f"mutation: {len(paths)} module(s), {tested} mutants tested in {elapsed_s:.0f} s "
          f"({elapsed_s / 60:.1f} min, --jobs {args.jobs})", file=sys.stderr)
    for path in below:
        result = results[path]
        print(f"mutation: {path} scores {result.score * 100:.1f} %"
              f"{'' if result.complete else f' so far, at most {best_score(result) * 100:.1f} %'}"
              f", below {args.min_score * 100:.1f} %", file=sys.stderr)
    if args.record:
        _record(results, list(configured))
    return 1 if below else 0


def _record(results: dict[str, ModuleResult | None], order: list[str]) -> None:
    """Write each module whose run completed to :data:`SCORES_FILE`, at HEAD and today's date
    (UTC); the others keep their records."""
    new = {path: last_scores.Scored(changed.head(ROOT),
                                    datetime.datetime.now(datetime.UTC).date().isoformat(),
                                    r.score)
           for path, r in results.items() if r is not None and r.complete}
    skipped = [path for path in results if path not in new]
    if new:
        records = last_scores.updated(last_scores.load(SCORES_FILE), new, order)
        SCORES_FILE.write_text(last_scores.render(records))
        print(f"mutation: --record: {len(new)} module(s) recorded at "
              f"{changed.head(ROOT)[:12]} in {SCORES_FILE.name}", file=sys.stderr)
    if skipped:
        print(f"mutation: --record: {len(skipped)} module(s) not recorded (their run did not "
              f"complete): {', '.join(skipped)}", file=sys.stderr)
