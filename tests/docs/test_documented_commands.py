"""Docs that cannot drift (README.md, docs/*.md, deploy/*.md).

- Every command of a ``sh``/``bash``/``console``/``shell`` block is either run (in a scratch
  folder that reaches the repository's files; background jobs, ``kill %N`` and a shortened
  variant where SHORTER says so) with its exit status and quoted output checked, or on SKIPS
  with a reason. A newly documented command is run unless SKIPS names it (so it fails until it
  runs, or is skipped with a reason), and an entry that matches no documented command fails.
- Every program invocation in a code span or block uses options the program's parser has,
  and the literal choices it gives are among the option's choices.
- Every ``toml`` block validates with the configuration (or scenario) loader, merged over the
  defaults, and so does every deploy/*.toml.
- A block of measured figures (us, Hz, wall time) is preceded by a line ``Measured with
  `COMMAND` on MACHINE, YYYY-MM-DD`` (docs/testing.md, "Docs tests").
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tomllib
import uuid
from dataclasses import dataclass
from pathlib import Path

import pytest

from haptic.common.config import load_config, override
from haptic.common.config.scenario import scenario_from_table
from haptic.common.wire.auth import write_key_file
from haptic.common.wire.link_config import link_config_from
from haptic.common.wire.ports import free_port
from tests.docs.doc_commands import (
    ROOT,
    SHELL_LABELS,
    Block,
    Command,
    Invocation,
    attribution,
    block_invocations,
    deploy_files,
    doc_files,
    fenced_blocks,
    figure_blocks,
    file_invocations,
    inline_spans,
    invocations,
    option_problems,
    prefetch_options,
    rel,
    shell_commands,
)
from tests.helpers.programs import Program

#: A foreground command's limit, and how long a background job may take to end by itself, s.
COMMAND_TIMEOUT_S = 180.0
JOB_END_S = 30.0


@dataclass(frozen=True)
class Skip:
    """A documented command the test does not run, and why."""

    file: str
    command: str
    reason: str


def _skip(file: str, reason: str, *commands: str) -> list[Skip]:
    """One reason for several commands of a file."""
    return [Skip(file, command, reason) for command in commands]


CI_INSTALLS = "the install and the test run that .ci/run performs on every change"
SKIPS: list[Skip] = [
    *_skip("README.md", CI_INSTALLS,
           "python3 -m pip install -c constraints.txt -e .",
           'python3 -m pip install -c constraints.txt -e ".[test]"', "python3 -m pytest"),
    *_skip("README.md", "fetches uv from the network and re-resolves every dependency "
           "(tests/deploy/test_dependency_lock.py checks the lock)", "python3 tools/lock.py"),
    *_skip("deploy/README.md", "real CAN hardware (the drives and the sensor on can0)",
           "haptic-master --config deploy/two-hosts.toml --rig can "
           "--json-summary out/master.json"),
    *_skip("deploy/README.md", "needs a second host: connects to the rig PC's address "
           "(tests/deploy/test_two_hosts.py runs the pair)",
           "haptic-slave --config deploy/two-hosts.toml --scenario constant-rate --out out/slave "
           "--json-summary out/slave.json"),
    *_skip("deploy/README.md", "needs a router host at deploy/router.toml's address "
           "(tests/deploy/test_link_deploy.py runs the three on loopback)",
           "haptic-router --listen tcp/0.0.0.0:7447 --insecure",
           "haptic-master --config deploy/router.toml",
           "haptic-slave --config deploy/router.toml"),
    *_skip("deploy/README.md", "root: writes into /etc/haptic",
           "python -c \"import secrets; print(secrets.token_hex(32))\" > /etc/haptic/rig-1.key",
           "chmod 600 /etc/haptic/rig-1.key",
           "deploy/make_certs.sh /etc/haptic/certs --san IP:192.168.1.5 --san DNS:router.lab"),
    *_skip("deploy/README.md", "root: a system user, a venv in /opt and files installed into "
           "/etc (udev, systemd)",
           "useradd --system --home-dir /var/lib/haptic --shell /usr/sbin/nologin haptic",
           "python3 -m venv /opt/haptic/venv",
           "/opt/haptic/venv/bin/pip install -c /path/to/haptic-teleop/constraints.txt "
           "/path/to/haptic-teleop",
           "install -d -m 0755 /etc/haptic /etc/haptic/zenoh",
           "install -d -m 0750 -g haptic /etc/haptic/certs",
           "install -m 0644 deploy/zenoh/*.json5 /etc/haptic/zenoh/",
           "install -m 0644 -g haptic certs/ca.pem certs/<this host>.pem /etc/haptic/certs/",
           "install -m 0640 -g haptic certs/<this host>.key /etc/haptic/certs/",
           "install -m 0644 deploy/router-tls.toml /etc/haptic/haptic.toml",
           "install -m 0644 deploy/systemd/haptic-<program>.service /etc/systemd/system/",
           "install -m 0644 deploy/udev/60-haptic-cpu-latency.rules /etc/udev/rules.d/",
           "udevadm control --reload", "udevadm trigger --sysname-match=cpu_dma_latency",
           "systemctl daemon-reload"),
    *_skip("deploy/README.md", "ip link: root and a real CAN interface (can0)",
           "ip link set can0 down", "ip link set can0 type can bitrate 1000000 restart-ms 100",
           "ip link set can0 txqueuelen 1000", "ip link set can0 up",
           "ip -details -statistics link show can0", "candump can0"),
    *_skip("docs/ros2.md", "ROS 2 only: needs a ROS 2 install with rmw_zenoh_cpp, foxglove_bridge "
           "(tests/common/ros2 check the wire format without one)",
           "ros2 run rmw_zenoh_cpp rmw_zenohd", "ros2 node list", "ros2 topic list -t",
           "ros2 topic echo /haptic/handle/wrench", "ros2 topic hz /haptic/tool/pose",
           "ros2 topic echo /diagnostics",
           "ros2 launch foxglove_bridge foxglove_bridge_launch.xml port:=8766",
           "ros2 bag record -o haptic_run /haptic/handle/wrench /haptic/handle/pose "
           "/haptic/handle/joint_states /haptic/tool/wrench /haptic/tool/pose /haptic/clay/points "
           "/tf /diagnostics", "ros2 bag info haptic_run"),
    *_skip("docs/ros2.md", "publishes to rmw_zenohd's fixed tcp/localhost:7447, which a test "
           "cannot assume is free; tests/common/ros2/test_ros2_session.py runs it against a "
           "router on a free port", "haptic-session --ros2 --duration 1"),
    *_skip("deploy/README.md", "systemd: the installed units on a deployed host",
           "systemctl enable --now haptic-router", "systemctl enable --now haptic-slave",
           "systemctl enable --now haptic-master", "systemctl status haptic-master",
           "systemctl stop haptic-master", "systemctl restart haptic-slave",
           "journalctl -u haptic-master -f", 'journalctl -u haptic-slave -b --since "10 min ago"',
           "journalctl -u haptic-router -p warning", "cat /var/lib/haptic/master.json"),
]

#: Commands run in a shorter form: (file, command) -> (what runs, why).
SHORTER: dict[tuple[str, str], tuple[str, str]] = {
    ("README.md", "haptic-session"): (
        "haptic-session --duration 1", "1 s of rig time; the README says so under the command"),
    ("README.md", "haptic-slave --duration 10 --out out/slave"): (
        "haptic-slave --duration 3 --out out/slave", "3 s instead of 10"),
    ("README.md", "haptic-master --operator regulate:fx=3.6,onset=0.2,max=5 --duration 10"): (
        "haptic-master --operator regulate:fx=3.6,onset=0.2,max=5 --duration 3",
        "3 s instead of 10"),
    ("docs/interfaces.md", "haptic-slave --duration 10 --record out/slave.mcap"): (
        "haptic-slave --duration 3 --record out/slave.mcap", "3 s instead of 10"),
    ("docs/interfaces.md", "haptic-master --operator regulate:fx=3.6,onset=0.2,max=5 "
     "--duration 10 --record out/master.mcap"): (
        "haptic-master --operator regulate:fx=3.6,onset=0.2,max=5 --duration 3 "
        "--record out/master.mcap", "3 s instead of 10"),
    ("docs/interfaces.md", "haptic-slave --duration 20"): (
        "haptic-slave --duration 3", "3 s instead of 20"),
    ("docs/interfaces.md", "haptic-master --operator regulate:fx=3.6,onset=0.2,max=5 "
     "--duration 20"): (
        "haptic-master --operator regulate:fx=3.6,onset=0.2,max=5 --duration 3",
        "3 s instead of 20"),
}


def _all_commands() -> list[tuple[Block, list[Command]]]:
    """Every shell block of the docs with its commands."""
    found = []
    for path in doc_files():
        for block in fenced_blocks(path):
            if block.label in SHELL_LABELS:
                found.append((block, shell_commands(block)))
    return found


def _skipped(command: Command) -> Skip | None:
    """The SKIPS entry of a command, if any."""
    return next((skip for skip in SKIPS
                 if (skip.file, skip.command) == (command.file, command.text)), None)


def _runnable_blocks() -> list[tuple[Block, list[Command]]]:
    """The shell blocks with at least one command to run."""
    return [(block, commands) for block, commands in _all_commands()
            if any(_skipped(command) is None for command in commands)]


def test_every_documented_command_is_run_or_skipped() -> None:
    """A command is run unless SKIPS names it; an entry of SKIPS or SHORTER that matches no
    documented command is stale."""
    documented = {(c.file, c.text) for _, commands in _all_commands() for c in commands}
    stale = [skip for skip in SKIPS if (skip.file, skip.command) not in documented]
    stale += [key for key in SHORTER if key not in documented]
    assert not stale, f"entries that match no documented command: {stale}"
    assert all(skip.reason for skip in SKIPS)


class Scratch:
    """A scratch folder as the commands' cwd, the repository's files linked into it, and the
    session's own endpoint, key prefix and view port so that runs never cross."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        for entry in ROOT.iterdir():
            if not entry.name.startswith(".") and entry.name != "out":
                (folder / entry.name).symlink_to(entry)
        bin_dir = folder / ".bin"
        bin_dir.mkdir()
        for name in ("python", "python3"):
            (bin_dir / name).symlink_to(sys.executable)
        self.env = {**os.environ, "TMPDIR": str(folder),
                    "PATH": f"{bin_dir}:{Path(sys.executable).parent}:{os.environ['PATH']}"}
        endpoint, prefix = f"tcp/127.0.0.1:{free_port()}", f"docs/{uuid.uuid4().hex[:8]}"
        self.own = {"haptic-master": f"--listen {endpoint} --key-prefix {prefix}",
                    "haptic-slave": f"--connect {endpoint} --key-prefix {prefix}",
                    "haptic-view": f"--connect {endpoint} --key-prefix {prefix} "
                                   f"--port {free_port()}"}

    def shell_text(self, command: Command) -> str:
        """What runs: the shorter variant, with this session's endpoint for a linked program."""
        text = SHORTER.get((command.file, command.text), (command.text, ""))[0]
        program, _, rest = text.partition(" ")
        if program in self.own and "--no-link" not in rest:
            text = f"{program} {self.own[program]} {rest}"
        return text


@dataclass
class Job:
    """A background job: its program (its own PID, ``exec``'d by bash) and what it ran."""

    command: Command
    program: Program

    def output(self) -> str:
        return self.program.output()[-3000:]


def _start(scratch: Scratch, command: Command) -> Job:
    program = Program(["bash", "-c", "exec " + scratch.shell_text(command)], cwd=scratch.folder,
                      env=scratch.env, stop_signal=signal.SIGTERM, new_session=True)
    return Job(command, program)


def _ended(job: Job, how: str) -> list[str]:
    """Wait for a job that was told to end (or ends by itself); its exit status must be 0."""
    status = job.program.ended_within(JOB_END_S)
    if status is None:
        status = job.program.stop(signal.SIGTERM, grace_s=JOB_END_S)
        how = "did not end by itself; after SIGTERM"
    if status == 0:
        return []
    return [f"{job.command.file}:{job.command.line} `{job.command.text}` ({how}) exited "
            f"{status}:\n{job.output()}"]


def _foreground(scratch: Scratch, command: Command) -> list[str]:
    """Run one command to its end; its status must be 0 and its quoted lines printed."""
    done = subprocess.run(["bash", "-c", scratch.shell_text(command)], cwd=scratch.folder,
                          env=scratch.env, capture_output=True, text=True,
                          timeout=COMMAND_TIMEOUT_S)
    where = f"{command.file}:{command.line} `{command.text}`"
    output = done.stdout + done.stderr
    if done.returncode != 0:
        return [f"{where} exited {done.returncode}:\n{output[-6000:]}"]
    printed = {line.strip() for line in output.splitlines()}
    return [f"{where} did not print the line the docs quote: {line!r}"
            for line in command.expected if line not in printed]


def run_block(scratch: Scratch, commands: list[Command], jobs: list[Job] | None = None
              ) -> list[str]:
    """Run a block's commands in order (background jobs, ``kill %N``, foreground); every job
    (in ``jobs``) is ended by its own PID and reaped, whatever happens."""
    jobs = [] if jobs is None else jobs
    problems: list[str] = []
    try:
        for command in commands:
            if _skipped(command):
                continue
            if command.text.startswith("kill %"):
                job = jobs[int(command.text.split("%")[1]) - 1]
                job.program.send_signal(signal.SIGTERM)
                problems += _ended(job, "kill %N: SIGTERM")
            elif command.background:
                jobs.append(_start(scratch, command))
            else:
                problems += _foreground(scratch, command)
        for job in jobs:
            if job.program.returncode is None and "--duration" not in job.command.text:
                job.program.send_signal(signal.SIGTERM)  # runs until signalled: the view
                problems += _ended(job, "left running by the docs; SIGTERM at the end")
            elif job.program.returncode is None:
                problems += _ended(job, "ends after its --duration")
    finally:
        for job in jobs:
            job.program.close()
    return problems


@pytest.mark.slow
@pytest.mark.parametrize("block,commands", _runnable_blocks(),
                         ids=[f"{b.file}:{b.line}" for b, _ in _runnable_blocks()])
def test_documented_commands_run(block: Block, commands: list[Command], tmp_path: Path) -> None:
    """The documented commands run and exit 0 (the long-lived ones shortened, SHORTER)."""
    scratch = Scratch(tmp_path)
    problems = run_block(scratch, commands)
    if problems:
        pytest.fail("\n".join(problems), pytrace=False)


def _documented_invocations(path: Path) -> list[Invocation]:
    """The program invocations of a doc file's blocks and inline code."""
    found = [inv for block in fenced_blocks(path) for inv in block_invocations(block)]
    found += [inv for line, span in inline_spans(path) for inv in invocations(rel(path), line,
                                                                               span)]
    return found


@pytest.fixture(scope="module")
def options_read() -> None:
    """The programs' options, read once for every file."""
    prefetch_options({inv.program for path in doc_files()
                      for inv in _documented_invocations(path)})


@pytest.mark.parametrize("path", doc_files(), ids=rel)
def test_documented_options_exist(path: Path, options_read: None) -> None:
    """Each ``--option`` of a documented invocation is the program's, by its exact name, and
    each literal choice is one of the option's."""
    problems = [f"{inv.file}:{inv.line}: {problem}" for inv in _documented_invocations(path)
                for problem in option_problems(inv)]
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("path", deploy_files(), ids=rel)
def test_deploy_files_name_real_options(path: Path, options_read: None) -> None:
    """The command lines in deploy/'s comments and systemd units use real options."""
    problems = [f"{inv.file}:{inv.line}: {problem}" for inv in file_invocations(path)
                for problem in option_problems(inv)]
    assert not problems, "\n".join(problems)


def _toml_blocks() -> list[Block]:
    """Every ``toml`` block of the docs."""
    return [block for path in doc_files() for block in fenced_blocks(path)
            if block.label == "toml"]


SCENARIO_TABLES = {"scenario", "grid", "tool", "operator", "workpiece", "blocks"}


def _check_scenario_snippet(table: dict, source: str) -> None:
    """A scenario snippet over the shipped constant-rate scenario; its workpiece (the list and
    the blocks) replaces the scenario's as a whole."""
    base_path = ROOT / "common/config/scenarios/constant-rate.toml"
    base = tomllib.loads(base_path.read_text())
    for name, value in table.items():
        if name in ("workpiece", "blocks") or not isinstance(value, dict):
            base[name] = value
        else:
            base[name] = {**base.get(name, {}), **value}
    scenario_from_table(base, source)


@pytest.mark.parametrize("block", _toml_blocks(), ids=lambda b: f"{b.file}:{b.line}")
def test_documented_toml_validates(block: Block, tmp_path: Path) -> None:
    """A TOML snippet is a partial configuration (merged over the defaults, as --config is)
    or a partial scenario; either validates."""
    table = tomllib.loads(block.text)
    if set(table) & SCENARIO_TABLES and not set(table) - SCENARIO_TABLES:
        _check_scenario_snippet(table, f"{block.file}:{block.line}")
        return
    path = tmp_path / "snippet.toml"
    path.write_text(block.text)
    load_config(path)


@pytest.mark.parametrize("path", sorted((ROOT / "deploy").glob("*.toml")), ids=rel)
def test_deploy_configurations_load(path: Path, tmp_path: Path) -> None:
    """The shipped deployment files load as they are, and give both sides a link
    configuration. The loader does not open the session key file it names (in /etc/haptic, on
    a deployed host); the link configuration reads it, so a fresh temporary key (64 hex
    digits, mode 600) stands in for it. Certificates are Zenoh's, read when a session opens."""
    config = load_config(path)
    if config["link"]["security"]["session_key_file"]:
        key = write_key_file(tmp_path / "rig.key")
        config = override(config, "link.security.session_key_file", str(key))
    for side in ("master", "slave"):
        link_config_from(config, side)


@pytest.mark.parametrize("path", doc_files(), ids=rel)
def test_quoted_figures_are_attributed(path: Path) -> None:
    """A pasted measurement says which command measured it, on what machine, when."""
    missing, unnamed = [], []
    for block in figure_blocks(path):
        match = attribution(path, block)
        if match is None:
            missing.append(f"{block.file}:{block.line}")
        elif not invocations(block.file, block.line, match.group(1)):
            unnamed.append(f"{block.file}:{block.line}: `{match.group(1)}`")
    assert not missing, ("blocks of measured figures without a 'Measured with `COMMAND` on "
                         f"MACHINE, YYYY-MM-DD' line just before: {missing}")
    assert not unnamed, f"the attribution names no program or bench/ script: {unnamed}"


def test_scratch_runner_reaps_its_jobs(tmp_path: Path) -> None:
    """The runner's own contract: a job left running is ended by its PID and reaped, and a
    failing command is reported with its status."""
    block = Block("docs/x.md", 1, "sh", ("sleep 300 &", "false"))
    scratch = Scratch(tmp_path)
    jobs: list[Job] = []
    problems = run_block(scratch, shell_commands(block), jobs)
    assert len(problems) == 2 and "exited 1" in problems[0] and "SIGTERM" in problems[1]
    assert [job.program.returncode for job in jobs] == [-signal.SIGTERM]
    quoted = Block("docs/x.md", 1, "console", ("$ echo one; echo two", "two", "$ echo 3", "4"))
    problems = run_block(scratch, shell_commands(quoted))
    assert problems == ["docs/x.md:4 `echo 3` did not print the line the docs quote: '4'"]


def test_the_readers_split_commands_and_find_stale_options() -> None:
    """The readers themselves: continuations, ``&&``, ``;``, ``&``, comments and quotes; a
    console block's output lines; an unknown option and a wrong choice are reported."""
    block = Block("docs/x.md", 1, "console", (
        "$ a --x 1 \\", "    --y 2 && b 'c;d' ; e &   # f", "printed", "$ g"))
    commands = shell_commands(block)
    assert [(c.text, c.background) for c in commands] == [
        ("a --x 1 --y 2", False), ("b 'c;d'", False), ("e", True), ("g", False)]
    assert commands[2].expected == ["printed"] and commands[3].line == 5
    synopsis = Block("docs/x.md", 1, "", ("haptic-sim sweep [--mode linear|cube]", "    [--nope]"))
    problems = [p for inv in block_invocations(synopsis) for p in option_problems(inv)]
    assert problems == ["haptic-sim sweep: --mode 'cube' is not one of ('linear', 'clay')",
                        "haptic-sim sweep: no option --nope"]
