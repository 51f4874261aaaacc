"""The [runner] table: CPU lists, validation through load_config, the settings it gives, and
the --spin-s / --rt-priority / --loop-cpus flags."""

from __future__ import annotations

import argparse
import os

import pytest

from haptic.common.config import ConfigError, exit_on_config_error, load_config
from haptic.common.config.runner_schema import parse_cpus
from haptic.common.runtime.cli_options import add_run_options, run_options_from_args
from haptic.common.runtime.realtime import RealtimeSettings
from haptic.common.runtime.runner_config import RunnerSettings, runner_settings_from

VALID = {
    "spin_s": "0.0002",
    "realtime_priority": "10",
    "tight_timers": "false",
    "loop_cpus": '"0"',
    "other_threads_cpus": '"0"',
    "gil_switch_interval_s": "0.0005",
    "zenoh_thread_priority": "5",
    "cpu_latency_limit_us": "-1",
    "zenoh_threads_batch": "false",
}


def runner_file(tmp_path, **changes: str):
    """A TOML file with a whole [runner] table (VALID with ``changes``; a value of None
    leaves the key out)."""
    table = {**VALID, **changes}
    lines = [f"{key} = {value}" for key, value in table.items() if value is not None]
    path = tmp_path / "runner.toml"
    path.write_text("[runner]\n" + "\n".join(lines) + "\n")
    return path


# --- parse_cpus ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "cpus"),
    [
        ("", ()),
        ("  ", ()),
        ("1", (1,)),
        ("0,2-3", (0, 2, 3)),
        ("3,1,1", (1, 3)),
        ("2-2", (2,)),
        (" 0 , 4-5 ", (0, 4, 5)),
        ("1,", (1,)),
    ],
)
def test_parse_cpus(text, cpus):
    assert parse_cpus(text) == cpus


@pytest.mark.parametrize("text", ["a", "-1", "3-1", "1-", "0-a", "1.5", "0;1", "1--2"])
def test_parse_cpus_rejects(text):
    with pytest.raises(ValueError):
        parse_cpus(text)


# --- the [runner] table through load_config -----------------------------------------------


def test_defaults():
    settings = runner_settings_from(load_config())
    assert settings == RunnerSettings(
        spin_s=0.0001,
        realtime=RealtimeSettings(priority=0, tight_timers=True, cpus=(),
                                  gil_switch_interval_s=0.0002, cpu_latency_limit_us=0),
    )
    assert load_config()["runner"]["loop_cpus"] == ""
    assert settings.other_threads_cpus == ()


def test_a_file_sets_the_whole_table(tmp_path):
    settings = runner_settings_from(load_config(runner_file(tmp_path)))
    assert settings == RunnerSettings(
        spin_s=0.0002,
        realtime=RealtimeSettings(priority=10, tight_timers=False, cpus=(0,),
                                  gil_switch_interval_s=0.0005),
        zenoh_thread_priority=5,
        zenoh_threads_batch=False,
        other_threads_cpus=(0,),
    )


@pytest.mark.parametrize(
    ("changes", "key"),
    [
        ({"busy_wait": "true"}, "runner.busy_wait"),
        ({"realtime_priority": "100"}, "runner.realtime_priority"),
        ({"realtime_priority": "-1"}, "runner.realtime_priority"),
        ({"realtime_priority": "1.5"}, "runner.realtime_priority"),
        ({"loop_cpus": '"a"'}, "runner.loop_cpus"),
        ({"loop_cpus": "1"}, "runner.loop_cpus"),  # a number, not a string
        ({"loop_cpus": f'"{os.cpu_count()}"'}, "runner.loop_cpus"),
        ({"spin_s": "-0.001"}, "runner.spin_s"),
        ({"spin_s": "0.5"}, "runner.spin_s"),
        ({"tight_timers": "1"}, "runner.tight_timers"),
        ({"other_threads_cpus": '"0;1"'}, "runner.other_threads_cpus"),
        ({"other_threads_cpus": f'"{os.cpu_count()}"'}, "runner.other_threads_cpus"),
        ({"gil_switch_interval_s": "-0.001"}, "runner.gil_switch_interval_s"),
        ({"gil_switch_interval_s": "1.0"}, "runner.gil_switch_interval_s"),
        ({"gil_switch_interval_s": "5e-7"}, "runner.gil_switch_interval_s"),
        ({"cpu_latency_limit_us": "-2"}, "runner.cpu_latency_limit_us"),
        ({"cpu_latency_limit_us": "0.5"}, "runner.cpu_latency_limit_us"),
        ({"zenoh_threads_batch": '"yes"'}, "runner.zenoh_threads_batch"),
    ],
)
def test_bad_values_name_the_key(tmp_path, changes, key):
    with pytest.raises(ConfigError) as caught:
        load_config(runner_file(tmp_path, **changes))
    assert caught.value.key == key
    assert str(caught.value).startswith(f"{key}: ")


def test_a_cpu_the_machine_lacks_says_how_many_it_has(tmp_path):
    count = os.cpu_count()
    with pytest.raises(ConfigError, match=f"it has {count}"):
        load_config(runner_file(tmp_path, loop_cpus=f'"0-{count}"'))


def test_settings_from_an_unvalidated_table_still_name_the_key():
    config = load_config()
    config["runner"] = {**config["runner"], "loop_cpus": "zero"}
    with pytest.raises(ConfigError) as caught:
        runner_settings_from(config)
    assert caught.value.key == "runner.loop_cpus"


# --- the command-line flags ---------------------------------------------------------------


def parse(argv: list[str], config_file=None):
    parser = argparse.ArgumentParser()
    add_run_options(parser)
    if config_file is not None:
        argv = ["--config", str(config_file), *argv]
    return run_options_from_args(parser.parse_args(argv), "master")


def test_flags_set_the_runner():
    options = parse(["--spin-s", "0.00005", "--rt-priority", "0", "--loop-cpus", "0",
                     "--other-cpus", "0", "--cpu-latency-us", "-1"])
    assert options.runner == RunnerSettings(
        spin_s=0.00005,
        realtime=RealtimeSettings(priority=0, tight_timers=True, cpus=(0,),
                                  gil_switch_interval_s=0.0002, cpu_latency_limit_us=-1),
        other_threads_cpus=(0,),
    )
    assert options.config["runner"]["realtime_priority"] == 0
    assert options.config["runner"]["cpu_latency_limit_us"] == -1


def test_no_flags_keep_the_defaults():
    assert parse([]).runner == runner_settings_from(load_config())


def test_flags_win_over_the_file(tmp_path):
    options = parse(["--rt-priority", "60"], config_file=runner_file(tmp_path))
    assert options.runner.realtime == RealtimeSettings(priority=60, tight_timers=False, cpus=(0,),
                                                       gil_switch_interval_s=0.0005)
    assert options.runner.spin_s == 0.0002  # from the file


def test_an_empty_loop_cpus_flag_means_any_cpu(tmp_path):
    options = parse(["--loop-cpus", "", "--other-cpus", ""], config_file=runner_file(tmp_path))
    assert options.runner.realtime.cpus == ()


@pytest.mark.parametrize(
    ("argv", "named"),
    [
        (["--rt-priority", "120"], "--rt-priority (runner.realtime_priority)"),
        (["--rt-priority", "-5"], "--rt-priority (runner.realtime_priority)"),
        (["--loop-cpus", "x"], "--loop-cpus (runner.loop_cpus)"),
        (["--loop-cpus", str(os.cpu_count())], "--loop-cpus (runner.loop_cpus)"),
        (["--spin-s", "-1"], "--spin-s (runner.spin_s)"),
        (["--other-cpus", "0-x"], "--other-cpus (runner.other_threads_cpus)"),
    ],
)
def test_bad_flags_name_the_flag(argv, named, capsys):
    with pytest.raises(ConfigError) as caught:
        parse(argv)
    assert str(caught.value).startswith(named)
    with pytest.raises(SystemExit) as exited, exit_on_config_error():
        parse(argv)
    assert exited.value.code == 2
    assert named in capsys.readouterr().err


def test_zenoh_thread_priority_must_stay_below_the_loop(tmp_path):
    from haptic.common.runtime.runner_config import runner_settings_from

    config = load_config(None)
    config["runner"]["realtime_priority"] = 40
    config["runner"]["zenoh_thread_priority"] = 40
    with pytest.raises(ConfigError) as error:
        runner_settings_from(config)
    assert error.value.key == "runner.zenoh_thread_priority"
    config["runner"]["zenoh_thread_priority"] = 30
    assert runner_settings_from(config).zenoh_thread_priority == 30


def test_zenoh_threads_are_batched_by_default_and_not_when_turned_off():
    from haptic.common.runtime.runner_config import prioritise_zenoh_threads, runner_settings_from

    config = load_config(None)
    settings = runner_settings_from(config)
    assert settings.zenoh_thread_priority == 0 and settings.zenoh_threads_batch
    summary = prioritise_zenoh_threads(settings)
    assert summary["zenoh_threads_batch"] is True and summary["zenoh_thread_warnings"] == []
    config["runner"]["realtime_priority"] = 40  # a FIFO loop: they cannot preempt it
    assert prioritise_zenoh_threads(runner_settings_from(config)) == {}
    config["runner"]["realtime_priority"] = 0
    config["runner"]["zenoh_threads_batch"] = False
    assert prioritise_zenoh_threads(runner_settings_from(config)) == {}


def test_place_other_threads_is_off_by_default():
    from haptic.common.runtime.runner_config import place_other_threads

    assert place_other_threads(runner_settings_from(load_config(None))) == {}


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="Linux CPU affinity")
def test_place_other_threads_pins_the_thread_and_what_it_starts_next():
    import threading

    from haptic.common.runtime.runner_config import place_other_threads

    allowed = sorted(os.sched_getaffinity(0))
    config = load_config(None)
    config["runner"]["other_threads_cpus"] = str(allowed[0])
    config["runner"]["loop_cpus"] = str(allowed[-1])
    settings = runner_settings_from(config)
    seen: dict[str, object] = {}

    def child() -> None:
        seen["child"] = os.sched_getaffinity(0)

    def body() -> None:  # in its own thread: affinity is per thread
        seen["keys"] = place_other_threads(settings)
        started = threading.Thread(target=child)
        started.start()
        started.join()

    thread = threading.Thread(target=body)
    thread.start()
    thread.join(timeout=10)
    assert seen["keys"] == {"other_threads_cpus": [allowed[0]], "other_threads_warnings": []}
    assert seen["child"] == {allowed[0]}
    assert sorted(os.sched_getaffinity(0)) == allowed  # the test's own thread is untouched


def test_other_threads_cpus_need_loop_cpus(tmp_path):
    config = load_config(runner_file(tmp_path, loop_cpus='""'))
    with pytest.raises(ConfigError) as caught:
        runner_settings_from(config)
    assert caught.value.key == "runner.other_threads_cpus"
    assert "needs runner.loop_cpus" in str(caught.value)
    with pytest.raises(ConfigError, match="needs runner.loop_cpus"):
        parse(["--other-cpus", "0", "--loop-cpus", ""])
