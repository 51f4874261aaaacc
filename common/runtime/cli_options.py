"""The one shared command-line helper of ``haptic-master`` and ``haptic-slave``.

Both programs call :func:`add_run_options` on their parser and :func:`run_options_from_args`
on the parsed arguments. Order of precedence, lowest first: the shipped defaults, the TOML
file of ``--config``, then the flags. For Zenoh itself: the ``--zenoh-config`` json5 file,
then the ``[link]`` settings and connection flags, then every ``--zenoh-set KEY=VALUE``.

A session that reaches other hosts needs a session key or mutual TLS, or ``--insecure``
(common/wire/protected_mode.py): :func:`run_options_from_args` refuses it otherwise.

Injection flags (``--one-way-delay``, ``--jitter``, ``--loss`` ...) set what *this side's receiving*
link injects, one way (``[link.<side>.injection]``). Every invalid value raises a
:class:`~haptic.common.config.ConfigError` naming the flag and the key; wrap the call in
:func:`~haptic.common.config.exit_on_config_error` to exit with status 2 and one line.

Example::

    parser = argparse.ArgumentParser(prog="haptic-slave")
    add_run_options(parser)
    args = parser.parse_args()
    with exit_on_config_error():
        options = run_options_from_args(args, side="slave")
    with Link(options.link) as link:
        ...
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from haptic.common.config import ConfigError, load_config, override
from haptic.common.config.link_schema import JITTER_DISTRIBUTIONS, MODES, SIDES
from haptic.common.runtime.runner_config import RunnerSettings, runner_settings_from
from haptic.common.wire.link_config import LinkConfig, link_config_from

# flag dest -> key under [link.<side>.injection]
_INJECTION_FLAGS = {
    "delay": ("--one-way-delay", "delay_s"),
    "jitter": ("--jitter", "jitter_s"),
    "jitter_distribution": ("--jitter-distribution", "jitter_distribution"),
    "loss": ("--loss", "loss_probability"),
    "burst_enter": ("--burst-enter", "burst_enter_probability"),
    "burst_exit": ("--burst-exit", "burst_exit_probability"),
    "burst_loss": ("--burst-loss", "burst_loss_probability"),
    "seed": ("--seed", "seed"),
    "delay_profile": ("--delay-profile", "delay_profile"),
}
# flag dest -> key under [runner]
_RUNNER_FLAGS = {
    "spin_s": ("--spin-s", "spin_s"),
    "rt_priority": ("--rt-priority", "realtime_priority"),
    "loop_cpus": ("--loop-cpus", "loop_cpus"),
    "other_cpus": ("--other-cpus", "other_threads_cpus"),
    "zenoh_priority": ("--zenoh-priority", "zenoh_thread_priority"),
    "cpu_latency_us": ("--cpu-latency-us", "cpu_latency_limit_us"),
}
# flag dest -> key under [link]
_LINK_FLAGS = {
    "mode": ("--mode", "transport.mode"),
    "key_prefix": ("--key-prefix", "transport.key_prefix"),
    "max_message_age": ("--max-message-age", "watchdog.max_message_age_s"),
    "session_key": ("--session-key", "security.session_key_file"),
    "insecure": ("--insecure", "security.insecure"),
}


@dataclass(frozen=True)
class RunOptions:
    """The validated options of one program run.

    ``config``: the whole validated configuration (with the flags applied); ``link``: this
    side's :class:`LinkConfig`; ``duration_s``: run length in s (``None``: until SIGINT or
    SIGTERM); ``json_summary``: where to write the JSON summary (or ``None``);
    ``show_status``: the live status line (``None``: when stderr is a terminal);
    ``runner``: the loop's pacing and scheduling (``[runner]``); ``max_steps``: end the run
    after this many ticks as well (``None``: no limit; the master's ``--rig-time``).
    """

    config: dict[str, Any]
    link: LinkConfig
    duration_s: float | None
    json_summary: Path | None
    show_status: bool | None
    runner: RunnerSettings
    max_steps: int | None = None


def add_run_options(parser: argparse.ArgumentParser) -> None:
    """Add ``--config``, ``--duration``, ``--json-summary``, ``--status``, the connection
    options and the injection options to ``parser``."""
    parser.add_argument("--config", metavar="FILE", help="TOML configuration (over the defaults)")
    parser.add_argument(
        "--duration", metavar="S", type=float, help="run for S seconds (default: until stopped)"
    )
    parser.add_argument("--json-summary", metavar="FILE", help="write the run summary as JSON")
    parser.add_argument(
        "--status", action=argparse.BooleanOptionalAction, default=None,
        help="live status line on stderr (default: when stderr is a terminal)",
    )
    parser.add_argument(
        "--record", metavar="FILE",
        help="record the run to an MCAP file (Foxglove, PlotJuggler; haptic-replay FILE)",
    )
    parser.add_argument(
        "--record-every", metavar="N", type=int, default=1,
        help="record the loop's state every Nth tick (default 1: every tick)",
    )
    parser.add_argument(
        "--display", action=argparse.BooleanOptionalAction, default=True,
        help="publish the status (and the slave's clay) at display rates for haptic-view "
        "(default: on)",
    )
    add_loop_options(parser)
    add_connection_options(parser)
    add_injection_options(parser)


def add_loop_options(parser: argparse.ArgumentParser) -> None:
    """The real-time loop's pacing and scheduling (``[runner]``)."""
    group = parser.add_argument_group("real-time loop")
    group.add_argument("--spin-s", metavar="S", type=float,
                       help="spin on the clock this long before each tick, s (runner.spin_s)")
    group.add_argument("--rt-priority", metavar="N", type=int,
                       help="SCHED_FIFO priority of the loop thread, 0 for normal scheduling "
                       "(runner.realtime_priority)")
    group.add_argument("--loop-cpus", metavar="CPUS",
                       help="CPUs of the loop thread, e.g. 1 or 0,2-3 (runner.loop_cpus)")
    group.add_argument("--other-cpus", metavar="CPUS",
                       help="CPUs of the program's other threads (Zenoh's, the display's), "
                       "e.g. 0 (runner.other_threads_cpus)")
    group.add_argument("--zenoh-priority", metavar="N", type=int,
                       help="SCHED_FIFO priority of Zenoh's threads, below --rt-priority; 0: "
                       "normal scheduling (runner.zenoh_thread_priority)")
    group.add_argument("--cpu-latency-us", metavar="US", type=int,
                       help="idle CPUs' exit latency limit held for the run, us (Linux PM QoS); "
                       "0: idle CPUs poll; -1: no request (runner.cpu_latency_limit_us)")


def add_connection_options(parser: argparse.ArgumentParser) -> None:
    """The Zenoh connection options (``[link.transport]``, ``[link.<side>.endpoints]``)."""
    group = parser.add_argument_group("connection (Zenoh)")
    group.add_argument(
        "--mode", choices=MODES, help="peer, or client of a router (link.transport.mode)"
    )
    group.add_argument(
        "--connect", metavar="ENDPOINT", action="append",
        help="endpoint to connect to, e.g. tcp/192.168.1.10:7447 (repeatable; replaces "
        "link.<side>.endpoints.connect; in client mode: the router)",
    )
    group.add_argument(
        "--listen", metavar="ENDPOINT", action="append",
        help="endpoint to listen on, e.g. tcp/0.0.0.0:7447 (repeatable; replaces "
        "link.<side>.endpoints.listen)",
    )
    group.add_argument("--key-prefix", metavar="PREFIX", help="key prefix, e.g. haptic/rig-1")
    group.add_argument("--session-key", metavar="FILE",
                       help="authenticate the session with the pre-shared key in FILE (64 hex "
                       "digits, mode 600; link.security.session_key_file)")
    group.add_argument(
        "--insecure", action="store_const", const=True, default=None,
        help="let a session that reaches other hosts (a non-loopback endpoint) run with neither "
        "a session key nor mutual TLS: anyone who reaches it can drive the handle and the tool "
        "(link.security.insecure; refused without it, exit 2)",
    )
    group.add_argument(
        "--zenoh-config", metavar="FILE", help="a Zenoh json5 configuration file, loaded first"
    )
    group.add_argument(
        "--zenoh-set", metavar="KEY=VALUE", action="append", default=[],
        help="a Zenoh configuration override, VALUE in json5, applied last (repeatable), "
        "e.g. transport/link/tx/queue/size/real_time=32",
    )
    group.add_argument(
        "--max-message-age", metavar="S", type=float,
        help="watchdog: safe state after S s without a fresh message "
        "(link.watchdog.max_message_age_s)",
    )


class _RetiredDelayOption(argparse.Action):
    """``--delay``: refused with the two options that say which delay is meant."""

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: Any, option_string: str | None = None) -> None:
        parser.error("--delay is ambiguous and not accepted: use --one-way-delay S (each "
                     "direction, what a receiving link injects) or --round-trip-delay S "
                     "(tau, both directions together, what the analysis and haptic-sim take)")


def add_retired_delay_option(parser: Any) -> None:
    """Refuse a bare ``--delay`` (it meant the round trip in some programs and one way in
    others) with an error naming ``--one-way-delay`` and ``--round-trip-delay``."""
    parser.add_argument("--delay", action=_RetiredDelayOption, help=argparse.SUPPRESS)


def add_injection_options(parser: argparse.ArgumentParser) -> None:
    """What this side's receiving link injects, one way (``[link.<side>.injection]``)."""
    group = parser.add_argument_group("injected impairment (this side's receiving link)")
    group.add_argument("--one-way-delay", dest="delay", metavar="S", type=float,
                       help="one-way delay of the messages this side receives, s")
    add_retired_delay_option(group)
    group.add_argument("--jitter", metavar="S", type=float, help="extra delay in [0, S], s")
    group.add_argument("--jitter-distribution", choices=JITTER_DISTRIBUTIONS)
    group.add_argument("--loss", metavar="P", type=float, help="independent loss probability")
    group.add_argument(
        "--burst-enter", metavar="P", type=float,
        help="bursty loss: probability per message of entering a burst (Gilbert-Elliott)",
    )
    group.add_argument(
        "--burst-exit", metavar="P", type=float,
        help="bursty loss: probability per message of leaving a burst (1/mean length)",
    )
    group.add_argument(
        "--burst-loss", metavar="P", type=float, help="bursty loss: loss probability in a burst"
    )
    group.add_argument("--seed", metavar="N", type=int, help="seed of the injected randomness")
    group.add_argument(
        "--delay-profile", metavar="PROFILE",
        help="one-way delay over time added to --one-way-delay, e.g. 'step 0:0.002 3:0.040' "
        "(2 ms, 40 ms from 3 s after the peer's first message) or 'linear 0:0.002 5:0.040' "
        "(a ramp); docs/governor.md",
    )


def _set(config: dict[str, Any], flag: str, key: str, value: Any) -> dict[str, Any]:
    try:
        return override(config, key, value)
    except ConfigError as error:
        message = str(error).removeprefix(f"{key}: ")
        raise ConfigError(f"{flag} ({key})", message) from None


def _zenoh_overrides(items: list[str]) -> tuple[tuple[str, str], ...]:
    result = []
    for item in items:
        key, equals, value = item.partition("=")
        if not equals or not key.strip() or not value.strip():
            raise ConfigError("--zenoh-set", f"{item!r} is not KEY=VALUE")
        result.append((key.strip(), value.strip()))
    return tuple(result)


def run_options_from_args(
    args: argparse.Namespace, side: str, config: dict[str, Any] | None = None
) -> RunOptions:
    """Validate the parsed arguments for ``side`` (``master`` or ``slave``) into
    :class:`RunOptions`. ``config`` replaces loading ``args.config`` (tests, embedding).
    Raises :class:`ConfigError` naming the flag or key; also checks that Zenoh accepts the
    resulting configuration."""
    if side not in SIDES:
        raise ConfigError("side", f"must be one of {', '.join(SIDES)} (got {side!r})")
    if config is None:
        config = load_config(getattr(args, "config", None))
    for dest, (flag, key) in _LINK_FLAGS.items():
        value = getattr(args, dest, None)
        if value is not None:
            config = _set(config, flag, f"link.{key}", value)
    for dest, (flag, key) in _RUNNER_FLAGS.items():
        value = getattr(args, dest, None)
        if value is not None:
            config = _set(config, flag, f"runner.{key}", value)
    for dest, (flag, key) in _INJECTION_FLAGS.items():
        value = getattr(args, dest, None)
        if value is not None:
            config = _set(config, flag, f"link.{side}.injection.{key}", value)
    for dest, flag in (("connect", "--connect"), ("listen", "--listen")):
        endpoints = getattr(args, dest, None)
        if endpoints:
            config = _set(config, flag, f"link.{side}.endpoints.{dest}", ",".join(endpoints))
    duration = getattr(args, "duration", None)
    if duration is not None and not duration > 0.0:
        raise ConfigError("--duration", f"must be > 0 s (got {duration:g})")
    zenoh_file = getattr(args, "zenoh_config", None)
    if zenoh_file is not None and not Path(zenoh_file).is_file():
        raise ConfigError("--zenoh-config", f"no such file {zenoh_file}")
    link = link_config_from(
        config,
        side,
        zenoh_config_file=zenoh_file,
        zenoh_overrides=_zenoh_overrides(getattr(args, "zenoh_set", None) or []),
    )
    check_zenoh_config(link)
    check_protected_mode(link)
    summary = getattr(args, "json_summary", None)
    return RunOptions(
        config=config,
        link=link,
        duration_s=duration,
        json_summary=Path(summary) if summary else None,
        show_status=getattr(args, "status", None),
        runner=runner_settings_from(config),
    )


def check_zenoh_config(link: LinkConfig) -> None:
    """Build the Zenoh configuration once so a bad file or override fails at start-up."""
    from haptic.common.wire.link import zenoh_config

    try:
        zenoh_config(link)
    except Exception as error:  # noqa: BLE001 - zenoh raises its own ZError
        flag = "--zenoh-config" if link.zenoh_config_file else "--zenoh-set"
        text = " ".join(str(error).split())[:240]
        raise ConfigError(flag, f"zenoh rejected the configuration: {text}") from None


def check_protected_mode(link: LinkConfig) -> None:
    """Refuse a session that reaches other hosts with neither a session key nor mutual TLS,
    unless ``link.insecure`` (:class:`ConfigError`, one line naming the ways out;
    common/wire/protected_mode.py). Before anything opens: nothing is sent."""
    from haptic.common.wire.link import zenoh_config
    from haptic.common.wire.protected_mode import require_protection

    require_protection(zenoh_config(link), link.session_key is not None, link.insecure)


def add_renamed_option(parser: Any, old: str, new: str) -> None:
    """Refuse ``old`` (an option that took one value) with an error naming ``new``, its
    spelling now (one vocabulary across the programs, docs/architecture.md)."""

    class _Renamed(argparse.Action):
        def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                     values: Any, option_string: str | None = None) -> None:
            parser.error(f"{old} is now {new}")

    parser.add_argument(old, action=_Renamed, help=argparse.SUPPRESS)
