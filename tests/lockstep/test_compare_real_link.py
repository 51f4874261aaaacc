"""The comparison's real-link cells, briefly (1 s of settling after the round trip, in real
time): one cell per lane law and one each of the paper's scheme and TDPA over real Zenoh on
loopback with 5 % loss, at settings where the lockstep's verdict is clear (far from the force
bound either way) and stays so over a wide range of round trips, since a loop that stalls on
a loaded machine runs at a shorter one than the network's. Each cell's verdict must agree
with the lockstep's, and its message path must account for every message: what a side sent
arrived, was lost by the injection, or was still in flight at the end; nothing else was
dropped."""

from __future__ import annotations

import json
import math

import pytest

from haptic.lockstep.cli import main
from haptic.lockstep.compare_grid import CompareGrid
from haptic.lockstep.compare_real_link import (
    RealLinkSet,
    lockstep_at_measured,
    real_link_text,
    run_real_link_cells,
)
from haptic.lockstep.compare_real_link_links import LagRecord

#: (control, task, round trip s, the lockstep's verdict there): wave and four-channel (with
#: and without its TDPA) bounded on the wall under 7 N at 200 ms and 1 s, the paper's scheme
#: unbounded on the 2 kN/m wall at every round trip (0 ms included), TDPA's sine under 1.4 N,
#: mmt's first touch of the wall at 1 s hundreds of N (and over 100 N at 0.4 s)
CLEAR_CELLS = [
    ("wave", "wall", 0.2, True),
    ("four-channel", "wall", 0.2, True),
    ("four-channel-tdpa", "wall", 0.2, True),
    ("mmt", "wall", 1.0, False),
    ("paper", "wall", 0.2, False),
    ("tdpa", "free-sine", 0.2, True),
]
ROUND_TRIP_S = 0.2
SETTLE_S = 1.0


def _check_message_path(link: dict, period_s: float, round_trip_s: float,
                        bounded: bool) -> None:
    """Sent = delivered + lost to the injection + in flight (at most the one-way delay's
    worth and a poll's budget); the loss near the injected 5 %; a bounded loop sends every
    message it computes."""
    dropped = dict(link["dropped"])
    lost = dropped.pop("injected_loss", 0)
    assert dropped == {}
    assert link["delivered"] + lost == link["expected"]
    in_flight = link["sent"] - link["expected"]
    assert 0 <= in_flight <= math.ceil(0.5 * round_trip_s / period_s) + 64
    assert 0.01 < lost / link["expected"] < 0.12
    if bounded:
        assert link["unsendable"] == 0


@pytest.mark.parametrize(("control", "task", "round_trip_s", "bounded"), CLEAR_CELLS,
                         ids=[f"{c}-{t}" for c, t, _, _ in CLEAR_CELLS])
def test_a_real_link_cell_agrees_with_the_lockstep(paper_model, control: str, task: str,
                                                   round_trip_s: float, bounded: bool) -> None:
    cells = RealLinkSet((control,), (task,), (round_trip_s,), settle_s=SETTLE_S)
    result = run_real_link_cells(cells, paper_model)
    (cell,) = result["cells"]
    assert cell["lockstep"]["bounded"] is bounded
    assert cell["real_link"]["bounded"] is bounded
    assert cell["agree"] and result["agreements"] == 1 and result["disagreements"] == 0
    real = cell["real_link"]
    assert real["measured_round_trip_s"] > 0.0
    for side in ("master", "slave"):
        _check_message_path(real["links"][side], paper_model.sample_period_s, round_trip_s,
                            bounded)
    assert f"{control:13s}" in real_link_text(result)


def test_an_off_target_cell_is_judged_at_its_measured_round_trip_too() -> None:
    """A wave wall cell the loop ran at 150 ms instead of 200 ms: the lockstep at 150 ms, of
    the same duration, says bounded too; a claimed unbounded real run disagrees with it."""
    cells = RealLinkSet(("wave",), ("wall",), (ROUND_TRIP_S,), settle_s=SETTLE_S)
    row = {"control": "wave", "task": "wall", "round_trip_s": ROUND_TRIP_S,
           "real_link": {"measured_round_trip_s": 0.15, "bounded": True}}
    assert lockstep_at_measured(cells, row, None) == {"round_trip_s": 0.15, "bounded": True,
                                                      "agree": True}
    row["real_link"]["bounded"] = False
    assert lockstep_at_measured(cells, row, None)["agree"] is False
    row["real_link"]["measured_round_trip_s"] = None
    assert lockstep_at_measured(cells, row, None) is None


def test_compare_real_link_adds_the_quick_cells_to_the_json(capsys) -> None:
    """``haptic-sim compare --quick --real-link --json`` for one control: the quick grid's
    JSON with the wall's two real-link cells (200 ms and 1 s), which agree."""
    assert main(["compare", "--quick", "--controls", "four-channel", "--real-link",
                 "--json"]) == 0
    data = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    real = data["real_link"]
    assert [(cell["task"], cell["round_trip_s"]) for cell in real["cells"]] == [
        ("wall", 0.2), ("wall", 1.0)]
    assert real["agreements"] == 2 and real["disagreements"] == 0
    quick = CompareGrid.quick(("four-channel",))
    assert real["settings"]["loss"] == 0.05
    assert len(data["cells"]) == len(quick.cell_lanes("four-channel"))


def test_the_lags_give_the_round_trip_and_the_share_of_ticks_on_target() -> None:
    """20 samples round trip (10 to the slave, 11 back, less the structural one) on 80 ticks
    of 100, 10 samples on the 20 a stall shortened; NaN before the first message."""
    lags = LagRecord(110)
    lags.to_slave[10:] = 10.0
    lags.to_master[10:] = 11.0
    lags.to_slave[60:80] = 5.0
    lags.to_master[60:80] = 6.0
    period = 0.001
    assert lags.share_within(0.020, 0.1, period) == pytest.approx(0.8)
    assert lags.share_within(0.010, 0.1, period) == pytest.approx(0.2)
    # the mean over the last three quarters (ticks 27 to 109): 63 ticks at 20, 20 at 10
    assert lags.round_trip_s(period) == pytest.approx((63 * 20 + 20 * 10) / 83 * period)
    assert LagRecord(10).share_within(0.02, 0.1, period) == 0.0
    assert math.isnan(LagRecord(10).round_trip_s(period))
