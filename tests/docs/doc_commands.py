"""Reading the documentation as data: fenced blocks, inline code spans, shell commands, the
program invocations in them, the programs' options and the quoted figures.

Used by tests/docs/test_documented_commands.py; no test lives here.
"""

from __future__ import annotations

import argparse
import importlib
import os
import re
import subprocess
import sys
import tomllib
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

#: Fence labels whose lines are shell commands (run or skipped, never ignored).
SHELL_LABELS = frozenset({"sh", "bash", "console", "shell"})

#: Parser-building functions of the console scripts that expose one; the others are read
#: from ``PROGRAM --help``.
PARSER_BUILDERS = {
    "haptic-analyze": "haptic.common.analysis.cli",
    "haptic-master": "haptic.master.cli",
    "haptic-rig-sim": "haptic.master.simulated_rig.cli",
    "haptic-sim": "haptic.lockstep.cli",
    "haptic-slave": "haptic.slave_sim.cli",
    "haptic-session": "haptic.common.launch.cli",
    "haptic-replay": "haptic.view.replay.cli",
    "haptic-view": "haptic.view.cli",
}

_FENCE = re.compile(r"^(\s*)```\s*([\w+-]*)")
_BENCH = re.compile(r"^(?:python3?\s+)?(bench/[a-z0-9_]+\.py)$")  # NAME: a placeholder


@dataclass(frozen=True)
class Block:
    """One fenced code block: its file (relative to the root), opening line and label."""

    file: str
    line: int
    label: str
    lines: tuple[str, ...]

    @property
    def text(self) -> str:
        """The block's text, as a file would hold it."""
        return "\n".join(self.lines) + "\n"


@dataclass
class Command:
    """One shell command of a block, as the docs give it, and the output lines they quote."""

    file: str
    line: int
    text: str
    background: bool = False
    expected: list[str] = field(default_factory=list)


def doc_files() -> list[Path]:
    """README.md, docs/*.md (and the folders under docs/, docs/measurements/) and deploy/*.md."""
    return [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md")),
            *sorted((ROOT / "deploy").glob("*.md"))]


def rel(path: Path) -> str:
    """A path relative to the repository root, as the docs write it."""
    return path.relative_to(ROOT).as_posix()


def fenced_blocks(path: Path) -> list[Block]:
    """Every fenced block of a Markdown file, the fence's indentation removed."""
    blocks, current, start, label, indent = [], None, 0, "", 0
    for number, line in enumerate(path.read_text().splitlines(), 1):
        match = _FENCE.match(line)
        if current is None and match:
            current, start, label, indent = [], number, match.group(2), len(match.group(1))
        elif current is not None and line.strip() == "```":
            blocks.append(Block(rel(path), start, label, tuple(current)))
            current = None
        elif current is not None:
            current.append(line[indent:] if line[:indent].strip() == "" else line)
    return blocks


def inline_spans(path: Path) -> list[tuple[int, str]]:
    """The inline code spans of the prose (outside fenced blocks): (line, text), a span that
    wraps over lines joined with a space."""
    lines = path.read_text().splitlines()
    prose, inside = [], False
    for line in lines:
        if _FENCE.match(line) or (inside and line.strip() == "```"):
            inside = not inside
            prose.append("")
        else:
            prose.append("" if inside else line)
    spans = []
    for paragraph_start, paragraph in _paragraphs(prose):
        for match in re.finditer(r"`([^`]+)`", paragraph):
            line = paragraph_start + paragraph.count("\n", 0, match.start())
            spans.append((line, " ".join(match.group(1).split())))
    return spans


def _paragraphs(lines: list[str]) -> list[tuple[int, str]]:
    """(first line number, text) of each run of non-blank lines."""
    result, start, current = [], 0, []
    for number, line in enumerate([*lines, ""], 1):
        if line.strip():
            if not current:
                start = number
            current.append(line)
        elif current:
            result.append((start, "\n".join(current)))
            current = []
    return result


def split_shell(line: str) -> list[tuple[str, bool]]:
    """A logical shell line cut at ``&&``, ``;`` and ``&`` outside quotes, its ``# comment``
    dropped: (command, runs in the background)."""
    parts, current, quote, i = [], "", "", 0
    while i < len(line):
        char = line[i]
        if quote:
            quote = "" if char == quote else quote
        elif char in "'\"":
            quote = char
        elif char == "#" and (not current or current[-1].isspace()):
            break
        elif line.startswith("&&", i) or char == ";":
            parts.append((current, False))
            current, i = "", i + (2 if char == "&" else 1)
            continue
        elif char == "&" and line[i - 1:i] != ">" and line[i + 1:i + 2] != ">":
            parts.append((current, True))
            current, i = "", i + 1
            continue
        current += char
        i += 1
    parts.append((current, False))
    return [(" ".join(text.split()), background) for text, background in parts if text.strip()]


def shell_commands(block: Block) -> list[Command]:
    """The commands of a shell block, backslash continuations joined. In a ``console`` block
    only ``$ `` lines are commands and the lines after one are its quoted output."""
    commands: list[Command] = []
    pending, pending_line = "", 0
    for number, raw in enumerate(block.lines, block.line + 1):
        if block.label == "console" and not raw.startswith("$ ") and not pending:
            if commands and raw.strip():
                commands[-1].expected.append(raw.strip())
            continue
        text = raw[2:] if block.label == "console" and raw.startswith("$ ") else raw
        if not pending:
            pending_line = number
        if text.rstrip().endswith("\\"):
            pending += text.rstrip()[:-1] + " "
            continue
        for command, background in split_shell(pending + text):
            commands.append(Command(block.file, pending_line, command, background))
        pending = ""
    return commands


def programs() -> set[str]:
    """The console scripts of pyproject.toml."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    return set(project["scripts"])


@dataclass(frozen=True)
class Invocation:
    """A program named in the docs with the tokens after it (up to the next program)."""

    file: str
    line: int
    program: str
    tokens: tuple[str, ...]


def invocations(file: str, line: int, text: str, first_only: bool = False) -> list[Invocation]:
    """The program invocations in one logical line of a code span or block (``first_only``:
    a shell command, whose program is its first word)."""
    names = programs()
    words = text.split()
    found: list[Invocation] = []
    i = 0
    while i < len(words) and not (first_only and i > 0):
        word = words[i].lstrip("$")
        bench = _BENCH.match(" ".join(words[i:i + 2])) if word.startswith("python") else None
        bench = bench or _BENCH.match(word)
        if word in names or bench:
            program = bench.group(1) if bench else word
            start = i + (2 if bench and word.startswith("python") else 1)
            end = start
            while end < len(words) and words[end] not in names and not _BENCH.match(
                    words[end]) and words[end] not in ("#", "&&", ";", "&", "|"):
                end += 1
            found.append(Invocation(file, line, program, tuple(words[start:end])))
            i = end
        else:
            i += 1
    return found


def block_invocations(block: Block) -> list[Invocation]:
    """Invocations in a fenced block: backslash continuations and, outside shell blocks, the
    lines indented under a synopsis line joined to it."""
    if block.label in SHELL_LABELS:
        return [inv for command in shell_commands(block)
                for inv in invocations(block.file, command.line, command.text, True)]
    found, logical, start, indent = [], "", 0, -1
    for number, raw in enumerate([*block.lines, ""], block.line + 1):
        depth = len(raw) - len(raw.lstrip())
        joined = logical.rstrip().endswith("\\") or (raw.strip() and indent >= 0 and
                                                     depth > indent)
        if joined:
            logical = logical.rstrip().rstrip("\\") + " " + raw.strip()
            continue
        if logical:
            found += invocations(block.file, start, logical.replace("$ ", " ", 1))
        logical, start, indent = raw, number, depth if raw.strip() else -1
    return found


def deploy_files() -> list[Path]:
    """The deployment files whose comments and unit lines give command lines."""
    deploy = ROOT / "deploy"
    return [*sorted(deploy.glob("*.toml")), *sorted(deploy.glob("zenoh/*.json5")),
            *sorted(deploy.glob("systemd/*.service"))]


def file_invocations(path: Path) -> list[Invocation]:
    """Invocations in a deployment file's comments (``#``, ``//``) and ``ExecStart=`` lines,
    a program's install path dropped and backslash continuations joined."""
    found, logical, start = [], "", 0
    for number, raw in enumerate(path.read_text().splitlines(), 1):
        text = raw.strip().lstrip("#/").strip().removeprefix("ExecStart=")
        text = re.sub(r"\S*/bin/(haptic-[\w-]+)", r"\1", text)
        if not logical:
            start = number
        if text.endswith("\\"):
            logical += text[:-1] + " "
            continue
        found += invocations(rel(path), start, logical + text)
        logical = ""
    return found


@dataclass(frozen=True)
class Options:
    """A parser's long options, each with its choices (None: any value); an option hidden
    from the help (a retired spelling) is not one."""

    choices: dict[str, tuple[str, ...] | None]
    subcommands: dict[str, Options]


def _from_parser(parser: argparse.ArgumentParser) -> Options:
    """The options of an argparse parser and of its subcommands' parsers."""
    choices: dict[str, tuple[str, ...] | None] = {}
    subcommands: dict[str, Options] = {}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            subcommands = {name: _from_parser(sub) for name, sub in action.choices.items()}
            continue
        for option in action.option_strings:
            if option.startswith("--") and action.help != argparse.SUPPRESS:
                choices[option] = tuple(map(str, action.choices)) if action.choices else None
    return Options(choices, subcommands)


def _from_help(text: str) -> Options:
    """The long options of a ``--help`` text (argparse's layout)."""
    choices: dict[str, tuple[str, ...] | None] = {}
    for line in text.splitlines():
        head = line.strip().split("  ")[0]
        if not line.startswith("  ") or not head.startswith("-"):
            continue
        for match in re.finditer(r"(--[\w-]+)(?:[ =]\{([^}]*)\})?", head):
            values = match.group(2)
            choices[match.group(1)] = tuple(values.split(",")) if values else None
    return Options(choices, {})


@cache
def program_options(program: str) -> Options:
    """The options of a console script or a ``bench/NAME.py`` script."""
    if program in PARSER_BUILDERS:
        return _from_parser(importlib.import_module(PARSER_BUILDERS[program]).build_parser())
    if program.startswith("bench/"):
        args = [sys.executable, str(ROOT / program), "--help"]
    else:
        args = [str(Path(sys.executable).parent / program), "--help"]
    done = subprocess.run(args, capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert done.returncode == 0, f"{program} --help: exit {done.returncode}\n{done.stderr}"
    return _from_help(done.stdout)


def prefetch_options(names: set[str]) -> None:
    """Read the ``--help`` of the programs without a parser builder in parallel (each imports
    its stack once, most of the options check's time)."""
    slow = sorted(name for name in names if name not in PARSER_BUILDERS)
    with ThreadPoolExecutor(max_workers=os.cpu_count() or 2) as pool:
        list(pool.map(program_options, slow))


def option_problems(invocation: Invocation) -> list[str]:
    """What in one documented invocation the program's parser does not have."""
    options = program_options(invocation.program)
    tokens = [token.strip("[](),") for token in invocation.tokens]
    name = invocation.program
    if options.subcommands and tokens and tokens[0] in options.subcommands:
        name, options = f"{name} {tokens[0]}", options.subcommands[tokens[0]]
    problems = []
    for i, token in enumerate(tokens):
        for option in token.split("|"):
            option = option.split("=")[0]
            if not re.fullmatch(r"--[a-z][\w-]*", option):
                continue
            if option not in options.choices:
                problems.append(f"{name}: no option {option}")
                continue
            allowed = options.choices[option]
            value = tokens[i + 1] if i + 1 < len(tokens) and "=" not in token else ""
            if "=" in token:
                value = token.split("=", 1)[1]
            if allowed and re.fullmatch(r"[a-z][\w+|-]*", value):
                problems += [f"{name}: {option} {choice!r} is not one of {allowed}"
                             for choice in value.split("|") if choice not in allowed]
    return problems


#: A figure a machine measured: a time in us or a rate in Hz, or wall-clock seconds.
MEASURED = re.compile(r"\d\s*(us|Hz)\b|\bwall\b")
#: The attribution a block of measured figures needs just before it.
ATTRIBUTION = re.compile(
    r"[Mm]easured with `([^`]+)`.*? on ([^,]+(?:, [^,0-9]+)*), (\d{4}-\d\d-\d\d)")


def figure_blocks(path: Path) -> list[Block]:
    """Unlabelled or ``text`` blocks that quote measured figures."""
    return [block for block in fenced_blocks(path) if block.label in ("", "text")
            and any(MEASURED.search(line) for line in block.lines)]


def attribution(path: Path, block: Block, lines_before: int = 4) -> re.Match[str] | None:
    """The ``Measured with `CMD` on MACHINE, YYYY-MM-DD`` line in the few non-blank lines
    before a block (the prose may wrap it)."""
    lines = path.read_text().splitlines()[:block.line - 1]
    text = [line for line in lines if line.strip()][-lines_before:]
    return ATTRIBUTION.search(" ".join(" ".join(text).split()))
