"""The comparison's real-link cells, briefly (1.2 s of simulated time each, in real time):
one cell per lane law and one each of the paper's scheme and TDPA over real Zenoh on loopback,
at 200 ms round trip with 5 % loss, at settings where the lockstep's verdict is clear (far
from the force bound either way). Each cell's verdict must agree with the lockstep's, and
its message path must account for every message: what a side sent arrived, was lost by the
injection, or was still in flight at the end; nothing else was dropped."""

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

#: (control, task, the lockstep's verdict there): bounded ones far under the 20 N bound,
#: unbounded ones far over it (mmt's wall model throws the handle out at 200 ms, the paper's
#: scheme is past its margin of a few ms)
CLEAR_CELLS = [
    ("wave", "wall", True),
    ("four-channel", "wall", True),
    ("mmt", "wall", False),
    ("paper", "wall", False),
    ("tdpa", "free-sine", True),
]
ROUND_TRIP_S = 0.2
SETTLE_S = 1.0


def _cell_set(control: str, task: str) -> RealLinkSet:
    return RealLinkSet((control,), (task,), (ROUND_TRIP_S,), settle_s=SETTLE_S)


def _check_message_path(link: dict, period_s: float, bounded: bool) -> None:
    """Sent = delivered + lost to the injection + in flight (at most the one-way delay's
    worth and a poll's budget); the loss near the injected 5 %; a bounded loop sends every
    message it computes."""
    dropped = dict(link["dropped"])
    lost = dropped.pop("injected_loss", 0)
    assert dropped == {}
    assert link["delivered"] + lost == link["expected"]
    in_flight = link["sent"] - link["expected"]
    assert 0 <= in_flight <= math.ceil(0.5 * ROUND_TRIP_S / period_s) + 64
    assert 0.01 < lost / link["expected"] < 0.12
    if bounded:
        assert link["unsendable"] == 0


@pytest.mark.parametrize(("control", "task", "bounded"), CLEAR_CELLS,
                         ids=[f"{c}-{t}" for c, t, _ in CLEAR_CELLS])
def test_a_real_link_cell_agrees_with_the_lockstep(paper_model, control: str, task: str,
                                                   bounded: bool) -> None:
    result = run_real_link_cells(_cell_set(control, task), paper_model)
    (cell,) = result["cells"]
    assert cell["lockstep"]["bounded"] is bounded
    assert cell["real_link"]["bounded"] is bounded
    assert cell["agree"] and result["agreements"] == 1 and result["disagreements"] == 0
    real = cell["real_link"]
    assert real["measured_round_trip_s"] > 0.0
    for side in ("master", "slave"):
        _check_message_path(real["links"][side], paper_model.sample_period_s, bounded)
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
