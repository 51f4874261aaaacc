"""The grid of ``haptic-sim compare`` and what one cell of it is (docs/architectures.md).

A cell is one control on one task over one network: a round-trip delay, a loss rate with its
model (independent losses, or Gilbert-Elliott bursts of the same mean rate) and a jitter bound.
Every cell of a control runs as one lane of one simulation. The tasks, the operator's hand and
the devices are plain data here so that the lane simulators and the report agree on them.
"""

from __future__ import annotations

from dataclasses import dataclass

from haptic.common.wire.injection import InjectionConfig

CONTROLS = ("paper", "tdpa", "wave", "four-channel", "four-channel-tdpa", "mmt")
TASKS = ("free-sine", "wall", "clay-cut")
#: The controls that run the clay cut: every one (the lockstep's clay for paper and tdpa, the
#: same Warp clay in the lane simulator for the others).
CLAY_CONTROLS = CONTROLS
#: The paper's constant-rate cut (section 4.1): its force, N, and speed, m/s.
PAPER_CUT_FORCE_N = 3.6
PAPER_CUT_SPEED_M_PER_S = 0.038
#: Round-trip delays of the full grid, s.
ROUND_TRIPS_S = (0.0, 0.010, 0.050, 0.100, 0.200, 0.400, 0.800, 1.500, 3.000)
LOSSES = (0.0, 0.05, 0.20, 0.50)
LOSS_MODELS = ("independent", "bursty")
JITTERS_S = (0.0, 0.010)
#: The quick grid (CI): few delays, no loss and 20 % bursty loss, no jitter.
QUICK_ROUND_TRIPS_S = (0.0, 0.050, 0.200)
QUICK_LOSSES = (0.0, 0.20)
QUICK_LOSS_MODELS = ("bursty",)
QUICK_JITTERS_S = (0.0,)
#: Mean length of a loss burst in the bursty model, messages (as ``haptic-sim sweep``).
BURST_LENGTH_MESSAGES = 10.0
#: Wall stiffnesses of the Z-width ladder, N/m (quick: every other one).
STIFFNESS_LADDER_N_PER_M = (100.0, 300.0, 1e3, 3e3, 1e4, 3e4, 1e5)
QUICK_STIFFNESS_LADDER_N_PER_M = (300.0, 3e3, 3e4)


@dataclass(frozen=True)
class TaskSettings:
    """The two tasks along x (SI units in the names).

    clay-cut: the paper's constant-rate cut in the lockstep's clay (lockstep/compare_paper.py)
    or the same Warp clay in the lane simulator, the hand pushing ``cut_push_force_N`` ramped
    in over ``cut_rise_s`` through the operator impedance;
    free-sine: the hand tracks a sine of ``sine_amplitude_m`` at ``sine_frequency_hz`` through
    a spring and damper (``track_*``, the simulated rig's tracking operator's gains);
    wall: the hand pushes with an intent force ramped from 0 to ``push_force_N`` over the first
    half of the run through the paper's operator impedance (``hand_*``) into a wall at
    ``wall_surface_m`` of ``wall_stiffness_N_per_m``.
    """

    sine_amplitude_m: float = 0.02
    sine_frequency_hz: float = 0.5
    track_stiffness_N_per_m: float = 200.0
    track_damping_N_s_per_m: float = 20.0
    push_force_N: float = 4.0
    wall_surface_m: float = 0.01
    wall_stiffness_N_per_m: float = 2000.0
    wall_damping_N_s_per_m: float = 0.0
    hand_mass_kg: float = 0.25
    hand_damping_N_s_per_m: float = 2.0
    hand_stiffness_N_per_m: float = 6.0
    #: clay-cut: the clay sweep's steady push (lockstep/sweep.py's ``CLAY_OPERATOR``), N,
    #: ramped in over ``cut_rise_s``, s, through the same operator impedance.
    cut_push_force_N: float = 3.6
    cut_rise_s: float = 1.0
    #: Simulated time after the longest round trip of the grid, s.
    settle_s: float = 6.0


@dataclass(frozen=True)
class BoundSettings:
    """A cell is bounded when every sample is finite, no force (operator's or environment's)
    exceeds ``force_bound_N`` and the devices' mean kinetic energy over the last quarter of the
    run stays under ``energy_bound_J`` (a sustained fast oscillation fails it)."""

    force_bound_N: float = 20.0
    energy_bound_J: float = 0.01
    master_mass_kg: float = 0.35
    slave_mass_kg: float = 1.0


@dataclass(frozen=True)
class Network:
    """One cell's link, the same both ways: round trip (s), loss rate, its model, jitter (s)."""

    round_trip_s: float
    loss: float
    loss_model: str
    jitter_s: float

    def injection(self) -> InjectionConfig | None:
        """What each line injects besides the whole-sample delay (None: nothing)."""
        if self.loss <= 0.0 and self.jitter_s <= 0.0:
            return None
        if self.loss_model == "bursty" and self.loss > 0.0:
            leave = 1.0 / BURST_LENGTH_MESSAGES
            return InjectionConfig(jitter_s=self.jitter_s, burst_exit_probability=leave,
                                   burst_enter_probability=min(1.0, self.loss * leave
                                                               / (1.0 - self.loss)),
                                   burst_loss_probability=1.0)
        return InjectionConfig(jitter_s=self.jitter_s, loss_probability=self.loss)

    @property
    def constant_delay(self) -> bool:
        """Whether the link is a pure constant delay (no loss, no jitter)."""
        return self.loss <= 0.0 and self.jitter_s <= 0.0


@dataclass(frozen=True)
class Lane:
    """One lane of a control's run: its task, network and wall stiffness (N/m; the wall task's
    own or a ladder rung); ``ladder`` marks the Z-width lanes, which are not cells."""

    task: str
    network: Network
    wall_stiffness_N_per_m: float
    ladder: bool = False


@dataclass(frozen=True)
class CompareGrid:
    """What a comparison runs."""

    controls: tuple[str, ...] = CONTROLS
    tasks: tuple[str, ...] = TASKS
    round_trips_s: tuple[float, ...] = ROUND_TRIPS_S
    losses: tuple[float, ...] = LOSSES
    loss_models: tuple[str, ...] = LOSS_MODELS
    jitters_s: tuple[float, ...] = JITTERS_S
    stiffness_ladder_N_per_m: tuple[float, ...] = STIFFNESS_LADDER_N_PER_M
    task: TaskSettings = TaskSettings()
    bounds: BoundSettings = BoundSettings()
    seed: int = 0

    def __post_init__(self) -> None:
        unknown = [c for c in self.controls if c not in CONTROLS]
        if unknown or not self.controls:
            raise ValueError(f"controls must be some of {', '.join(CONTROLS)} (got {unknown})")
        if any(t not in TASKS for t in self.tasks):
            raise ValueError(f"tasks must be some of {', '.join(TASKS)}")
        if any(m not in LOSS_MODELS for m in self.loss_models):
            raise ValueError(f"loss models must be some of {', '.join(LOSS_MODELS)}")
        if any(not 0.0 <= loss < 1.0 for loss in self.losses):
            raise ValueError("losses must be in [0, 1)")

    @classmethod
    def quick(cls, controls: tuple[str, ...] = CONTROLS) -> CompareGrid:
        """The CI grid: 3 delays x 2 losses x 1 jitter x the tasks."""
        return cls(controls, TASKS, QUICK_ROUND_TRIPS_S, QUICK_LOSSES, QUICK_LOSS_MODELS,
                   QUICK_JITTERS_S, QUICK_STIFFNESS_LADDER_N_PER_M, TaskSettings(settle_s=3.0))

    @property
    def duration_s(self) -> float:
        """Every lane's run length: the longest round trip plus the settling time, s."""
        return max(self.round_trips_s) + self.task.settle_s

    def networks(self) -> list[Network]:
        """Every network of the grid; a zero loss has one loss model (independent)."""
        networks = []
        for round_trip in self.round_trips_s:
            for jitter in self.jitters_s:
                for loss in self.losses:
                    models = ("independent",) if loss <= 0.0 else self.loss_models
                    networks.extend(Network(round_trip, loss, model, jitter) for model in models)
        return networks

    def cell_lanes(self, control: str | None = None) -> list[Lane]:
        """The cells of one control (None: of any), task by task; the clay cut only for
        :data:`CLAY_CONTROLS`."""
        wall = self.task.wall_stiffness_N_per_m
        tasks = [task for task in self.tasks
                 if task != "clay-cut" or control is None or control in CLAY_CONTROLS]
        return [Lane(task, network, wall) for task in tasks for network in self.networks()]

    def ladder_lanes(self) -> list[Lane]:
        """The Z-width lanes of one control: the wall task at each delay and ladder stiffness,
        over a constant delay."""
        return [Lane("wall", Network(round_trip, 0.0, "independent", 0.0), stiffness, True)
                for round_trip in self.round_trips_s
                for stiffness in self.stiffness_ladder_N_per_m]


__all__ = ["CLAY_CONTROLS", "CONTROLS", "LOSS_MODELS", "PAPER_CUT_FORCE_N",
           "PAPER_CUT_SPEED_M_PER_S", "TASKS", "BoundSettings", "CompareGrid", "Lane",
           "Network", "TaskSettings"]
