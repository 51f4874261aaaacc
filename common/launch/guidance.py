"""What ``haptic-session`` tells a newcomer around the figures: how long the session will take
before it starts, and, when the real-time verdict is missed, what that means, what still holds
and what to try.

Light on purpose (no Warp, no numpy): it runs before the programs start.
"""

from __future__ import annotations

import importlib.metadata
import math
import os
import textwrap
from pathlib import Path
from typing import Any

#: Wall time a warm session spends outside the rig's time (interpreters, Zenoh, Warp's module
#: loads, the peer wait, the report and its plots), s: an estimate for the start line.
WARM_START_ESTIMATE_S = 14.0
#: Extra wall time of a first session on a machine, while Warp compiles the project's kernels
#: into its kernel cache, s: an estimate for the start line.
KERNEL_COMPILE_ESTIMATE_S = 15.0
#: The paper's constant-rate cut (Fig. 9): mean tool force, N, and speed, m/s.
PAPER_CUT_FORCE_N = 3.6
PAPER_CUT_SPEED_M_S = 0.038
#: How far the session's cut may sit from the paper's figures and still be called a match.
CUT_MATCH_TOLERANCE = 0.15


def warp_kernel_cache_dir() -> Path | None:
    """Warp's kernel cache folder as Warp chooses it (``WARP_CACHE_PATH``, else the user cache
    folder per Warp version), without importing Warp; None when Warp is not installed."""
    try:
        version = importlib.metadata.version("warp-lang")
    except importlib.metadata.PackageNotFoundError:
        return None
    configured = os.environ.get("WARP_CACHE_PATH")
    if configured:
        return Path(configured)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "warp" / version


def kernels_cached(cache_dir: Path | None) -> bool:
    """True when the cache folder holds kernels of this project (a later session loads them
    in milliseconds); False for an empty or missing cache (they are compiled first)."""
    return cache_dir is not None and any(cache_dir.glob("wp_haptic.*"))


def expected_duration_line(rig_time_s: float, cached: bool) -> str:
    """The start line's promise: about how long the session takes in wall time, and why a
    first run takes longer."""
    estimate_s = rig_time_s + WARM_START_ESTIMATE_S
    text = (f"haptic-session: expect about {estimate_s:.0f} s of wall time: {rig_time_s:g} s of "
            f"the rig's time, plus starting both programs and writing the report")
    if not cached:
        text += (f"; this first run on the machine also compiles Warp's kernels "
                 f"(about {KERNEL_COMPILE_ESTIMATE_S:.0f} s more, once)")
    return text + "; a loaded machine takes longer, and the cut still runs to its end"


def _within(value: Any, target: float) -> bool:
    return (isinstance(value, int | float) and math.isfinite(value)
            and abs(value - target) <= CUT_MATCH_TOLERANCE * target)


def what_still_holds(slave: dict[str, Any], gap_target_m: float,
                     trips_during_run: int) -> list[str]:
    """The results a missed verdict leaves standing, each checked against its figure: the cut
    against the paper, the final alignment, no watchdog trip."""
    held = []
    if (_within(slave.get("cut_mean_force_N"), PAPER_CUT_FORCE_N)
            and _within(slave.get("cut_mean_speed_m_s"), PAPER_CUT_SPEED_M_S)):
        held.append("the cut matches the paper (3.6 N at 38 mm/s, within 15 %)")
    gap = slave.get("final_position_gap_m")
    if gap and all(isinstance(g, int | float) and abs(g) <= gap_target_m for g in gap):
        held.append(f"the tool ends aligned with the handle (<= {gap_target_m * 1e3:g} mm)")
    if trips_during_run == 0:
        held.append("no watchdog tripped")
    return held


def missed_guidance_lines(slave: dict[str, Any], gap_target_m: float,
                          trips_during_run: int) -> list[str]:
    """What a missed real-time verdict means, what still holds, and what to try."""
    paragraphs = [
        "what this means: some ticks ran late or were skipped on this host, so the loops' "
        "timing is not what a rig PC must give the operator; the session itself completed, "
        "and the physics runs on the sample clock, so its results do not depend on it.",
    ]
    held = what_still_holds(slave, gap_target_m, trips_during_run)
    if held:
        paragraphs.append("still holds: " + "; ".join(held) + ".")
    paragraphs.append(
        "to try: a quieter host (no other busy process), `--rig model` (the rig's model in "
        "the master's process, without the emulated drives' process), or a rig PC with "
        "isolated CPUs and SCHED_FIFO (deploy/README.md).")
    return [line for text in paragraphs
            for line in textwrap.wrap(text, width=96, initial_indent="    ",
                                      subsequent_indent="      ")]
