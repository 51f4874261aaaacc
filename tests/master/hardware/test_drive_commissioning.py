"""The drives' commissioning plan (master/hardware/drive_commissioning.py) on its own: what
:func:`plan_drives` makes of the configured drives' EDS files, and that the plan it hands the
driver cannot change after it was made."""

from __future__ import annotations

import dataclasses

import pytest

from haptic.common.config import load_config, override
from haptic.master.hardware.drive_commissioning import plan_drives
from haptic.master.settings import master_settings

PERIOD_S = 0.00054


def test_the_shipped_drives_plan_one_plan_per_axis_with_the_sync_counter_on() -> None:
    """The packaged EDS has a writable 0x1019: both drives planned, no fallback, the SYNC
    counter on at the configured overflow."""
    settings = master_settings(load_config()).can
    plans = plan_drives(settings, PERIOD_S, fd=False)
    assert len(plans.plans) == len(settings.node_ids) == 2
    assert plans.fallbacks == []
    assert plans.sync_counter_overflow == settings.sync_counter_overflow > 0
    assert plans.sync_counter_note == f"SYNC counter 1..{settings.sync_counter_overflow}"


def test_a_counter_switched_off_is_said_and_is_no_fallback() -> None:
    settings = master_settings(override(load_config(), "master.can.sync_counter_overflow",
                                        0)).can
    plans = plan_drives(settings, PERIOD_S, fd=False)
    assert plans.sync_counter_overflow == 0
    assert plans.sync_counter_note == ("SYNC counter off ([master.can] sync_counter_overflow "
                                       "= 0)")
    assert plans.fallbacks == []


def test_the_plans_cannot_change_once_made() -> None:
    """The driver reads the plans while it commissions and cycles: a plan changed in between
    would configure one thing and run another."""
    plans = plan_drives(master_settings(load_config()).can, PERIOD_S, fd=False)
    with pytest.raises(dataclasses.FrozenInstanceError):
        plans.sync_counter_overflow = 0  # type: ignore[misc]
    with pytest.raises(dataclasses.FrozenInstanceError):
        plans.fallbacks = ["changed"]  # type: ignore[misc]
