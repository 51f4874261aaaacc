"""The watchdog's default resync tolerance as the programs offer it: |yt - Ah1 yh| below 1 mm
on both axes (docs/programs.md), the default of both networked programs' --sync-tolerance."""

from __future__ import annotations

import pytest

from haptic.common.runtime.watchdog import DEFAULT_SYNC_TOLERANCE_M
from haptic.master.cli import build_parser as master_parser
from haptic.slave_sim.cli import build_parser as slave_parser


def test_the_default_sync_tolerance_is_1_mm() -> None:
    assert DEFAULT_SYNC_TOLERANCE_M == pytest.approx(0.001, rel=1e-12)


@pytest.mark.parametrize("build_parser", [master_parser, slave_parser],
                         ids=["haptic-master", "haptic-slave"])
def test_both_programs_resync_within_1_mm_unless_told(build_parser) -> None:  # noqa: ANN001
    assert build_parser().parse_args([]).sync_tolerance == pytest.approx(0.001, rel=1e-12)
    assert build_parser().parse_args(["--sync-tolerance", "0.002"]).sync_tolerance == 0.002
