"""Every console script's ``--help``: it answers (exit status 0) with a description of whole
sentences without reST markup, and a parser that refuses an abbreviated or retired option
instead of expanding it to another one. The networked programs' parsers are built without
the heavy modules (Warp, python-control, scipy, matplotlib), so ``--help`` answers at once."""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import subprocess
import sys
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPTS = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
BENCH_SCRIPTS = sorted(path.stem for path in (ROOT / "bench").glob("*.py")
                       if "argparse.ArgumentParser(" in path.read_text())
#: What building a parser must not import (seconds of start-up between them).
HEAVY = ("warp", "control", "scipy", "matplotlib")


def _main(target: str) -> Callable[..., Any]:
    module, _, name = target.partition(":")
    return getattr(importlib.import_module(module), name)


@pytest.mark.parametrize("script", sorted(SCRIPTS))
def test_help_is_whole_sentences_without_markup(script: str, capsys) -> None:
    with pytest.raises(SystemExit) as stop:
        _main(SCRIPTS[script])(["--help"])
    assert stop.value.code == 0
    text = capsys.readouterr().out
    assert text.startswith(f"usage: {script} ")
    description = " ".join(text.split("\n\n")[1].split())
    assert description[0].isupper() and description.endswith("."), description
    assert "`" not in text


def _parsers_made_by(call: Callable[[], Any], monkeypatch: pytest.MonkeyPatch
                     ) -> list[argparse.ArgumentParser]:
    """The parsers ``call`` parses with (it is stopped at its first parse)."""
    seen: list[argparse.ArgumentParser] = []

    def stop(self: argparse.ArgumentParser, *args: Any, **kwargs: Any) -> Any:
        seen.append(self)
        raise SystemExit(0)

    monkeypatch.setattr(argparse.ArgumentParser, "parse_known_args", stop)
    with pytest.raises(SystemExit):
        call()
    return seen


@pytest.mark.parametrize("script", sorted(SCRIPTS))
def test_console_scripts_take_no_abbreviations(script: str, monkeypatch) -> None:
    parsers = _parsers_made_by(lambda: _main(SCRIPTS[script])([]), monkeypatch)
    assert parsers and not any(parser.allow_abbrev for parser in parsers)


@pytest.mark.parametrize("name", BENCH_SCRIPTS)
def test_bench_scripts_take_no_abbreviations(name: str, monkeypatch) -> None:
    spec = importlib.util.spec_from_file_location(name, ROOT / "bench" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, name, module)  # its dataclasses look themselves up
    spec.loader.exec_module(module)
    monkeypatch.setattr(sys, "argv", [name])
    parsers = _parsers_made_by(lambda: module.main(), monkeypatch)
    assert parsers and not any(parser.allow_abbrev for parser in parsers)


@pytest.mark.parametrize(("target", "argv"), [
    ("haptic.master.cli:main", ["--trace", "5"]),  # not --trace-every
    ("haptic.slave_sim.cli:main", ["--trace", "5"]),
    ("haptic.lockstep.cli:main", ["sweep", "--dur", "2"]),  # a subcommand's option
    ("haptic.common.analysis.cli:main", ["--round", "0.01"]),
    ("haptic.common.launch.cli:main", ["--dur", "1"]),
])
def test_a_prefix_of_an_option_is_refused(target: str, argv: list[str], capsys) -> None:
    with pytest.raises(SystemExit) as stop:
        _main(target)(argv)
    assert stop.value.code == 2
    assert "unrecognized arguments" in capsys.readouterr().err


@pytest.mark.parametrize("module", ["haptic.master.cli", "haptic.slave_sim.cli",
                                    "haptic.common.launch.cli", "haptic.lockstep.cli",
                                    "haptic.common.analysis.cli"])
def test_building_the_parser_imports_nothing_heavy(module: str) -> None:
    """In a fresh interpreter: import the CLI module, build its parser, list what loaded.
    (Zenoh's module loads in milliseconds; the link options' modules bring it.)"""
    code = (f"import sys, {module} as cli; cli.build_parser(); "
            f"print(' '.join(n for n in {HEAVY!r} if n in sys.modules))")
    loaded = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            check=True, timeout=120).stdout.split()
    assert loaded == [], loaded
