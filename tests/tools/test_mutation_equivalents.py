"""The data files: the equivalents loader refuses a bad entry by name, the configured modules
load, and every listed equivalent mutant is still made by the sources as they are."""

from __future__ import annotations

from pathlib import Path

import pytest

from tools.mutation import equivalents, modules
from tools.mutation.mutants import mutants

ROOT = Path(__file__).resolve().parents[2]

GOOD = """\
[[equivalent]]
module = "common/runtime/watchdog.py"
operator = "core/NumberReplacer"
line = "x = 0"
mutant = "x = 1"
reason = "x is set again before it is read"
"""


def test_a_good_entry_loads() -> None:
    (entry,) = equivalents.parse(GOOD)
    assert (entry.module, entry.line, entry.mutant, entry.above) == (
        "common/runtime/watchdog.py", "x = 0", "x = 1", "")


@pytest.mark.parametrize(("change", "message"), [
    (lambda t: t.replace('reason = "x is set again before it is read"\n', ""),
     "missing reason"),
    (lambda t: t.replace('reason = "x is set again before it is read"', 'reason = ""'),
     "reason must be a non-empty string"),
    (lambda t: t.replace('reason = "x is set again before it is read"',
                         'reason = """one\ntwo"""'), "one line"),
    (lambda t: t + 'why = "extra"\n', "unknown key(s) why"),
    (lambda t: t.replace("core/NumberReplacer", "core/Nonsense"), "core/Nonsense"),
    (lambda t: t + "\n" + t, "entry 2 (common/runtime/watchdog.py: 'x = 0' -> 'x = 1'): "
     "listed twice"),
    (lambda t: t.replace("[[equivalent]]", "[[equivalents]]"), "unknown top-level key"),
])
def test_a_bad_entry_is_refused_with_a_message_naming_it(change, message: str) -> None:
    with pytest.raises(equivalents.EquivalentsError) as caught:
        equivalents.parse(change(GOOD), "eq.toml")
    assert message in str(caught.value)
    if "top-level" not in message:
        assert str(caught.value).startswith("eq.toml: entry ")
        assert "common/runtime/watchdog.py: 'x = 0' -> 'x = 1'" in str(caught.value)


def test_an_entry_of_a_module_not_configured_is_refused() -> None:
    with pytest.raises(equivalents.EquivalentsError, match="not a configured module"):
        equivalents.parse(GOOD, modules=frozenset({"master/node.py"}))


def test_the_modules_file_is_checked(tmp_path: Path) -> None:
    (tmp_path / "a.py").write_text("")
    assert modules.parse('modules = ["a.py"]\n[every]\n"a.py" = 3\n[depth]\n"a.py" = 2\n',
                         tmp_path) == [modules.Configured("a.py", every=3, depth=2)]
    assert modules.parse('max_test_files = 3\nmodules = ["a.py"]\n',
                         tmp_path)[0].max_test_files == 3
    for text, message in (('modules = ["b.py"]\n', "no Python file"),
                          ('modules = ["a.py", "a.py"]\n', "listed twice"),
                          ('modules = ["a.py"]\ntests = {}\n', "unknown key"),
                          ('modules = ["a.py"]\n[every]\n"a.py" = 0\n', ">= 1"),
                          ('modules = []\n[every]\n"a.py" = 2\n', "not in modules"),
                          ('modules = ["a.py"]\n[depth]\n"a.py" = true\n', "integer"),
                          ('max_test_files = 0\nmodules = ["a.py"]\n', "max_test_files"),
                          ('max_test_files = 2.5\nmodules = ["a.py"]\n', "max_test_files"),
                          ('tests_cap_s = 60\nmodules = ["a.py"]\n', "unknown key")):
        with pytest.raises(modules.ModulesError, match=message):
            modules.parse(text, tmp_path)


def test_the_shipped_files_load() -> None:
    configured = modules.load(ROOT)
    assert len(configured) > 20
    entries = equivalents.load(modules=frozenset(c.path for c in configured))
    assert entries and all(e.reason for e in entries)


def test_every_listed_equivalent_mutant_is_still_made() -> None:
    """An entry whose line has changed must be re-examined, not silently kept."""
    entries = equivalents.load()
    made = {}
    for path in {e.module for e in entries}:
        listed = {e.line for e in entries if e.module == path}
        made[path] = mutants(ROOT, path, listed.__contains__)  # the listed lines' mutants
    # entry by entry: several share a reason, and one left stale must not hide behind another
    stale = [(e.module, e.line, e.mutant) for e in entries
             if not any(e.matches(m) for m in made[e.module])]
    assert stale == []
    # a line listed with the line above it matches that occurrence only
    kernel = [m for m in made["master/node_kernels.py"] if m.after == "if code > 0:"]
    assert len(kernel) == 3  # the trips' first block, the workspace block, the trip count
    assert [equivalents.reason_for(m, entries) is None for m in kernel] == [True, False, True]
