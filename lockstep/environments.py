"""The tool environments the lockstep simulator runs, in a module of its own so that
``haptic-sim``'s parser can offer them without importing the simulator (Warp, python-control)."""

from __future__ import annotations

#: "linear" (ft = Tt yt, the model's impedance), "clay" (the Warp clay) or "clay+linear"
#: (their sum).
ENVIRONMENTS = ("linear", "clay", "clay+linear")
