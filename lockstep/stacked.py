"""A linear block with one set of matrices per lane, for sweeps where lanes differ in k.

:class:`StackedLTI` has the interface the nodes use of a
:class:`~haptic.common.model.lti.DiscreteLTI` (``step``, ``initial_state``, names,
period) but its matrices have a leading lane axis, so
lanes with different compensators (different Ch1 gains) step together in one batched
matrix product instead of one batch per gain.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from haptic.common.model.lti import DiscreteLTI


@dataclass(frozen=True, eq=False)
class StackedLTI:
    """x[k+1] = A_l x[k] + B_l u[k], y[k] = C_l x[k] + D_l u[k] for each lane l.

    ``A`` (lanes, n, n), ``B`` (lanes, n, m), ``C`` (lanes, p, n), ``D`` (lanes, p, m)."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    period_s: float
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]

    def __post_init__(self) -> None:
        # [[C, D], [A, B]] per lane: one batched product per step for the outputs and the
        # next state together (four small batched products cost twice as much), and the
        # stacked [x; u] it multiplies
        lanes, n, m = self.B.shape
        p = self.C.shape[1]
        system = np.zeros((lanes, p + n, n + m))
        system[:, :p, :n], system[:, :p, n:] = self.C, self.D
        system[:, p:, :n], system[:, p:, n:] = self.A, self.B
        object.__setattr__(self, "_system", system)
        object.__setattr__(self, "_stacked", np.zeros((lanes, n + m, 1)))

    @classmethod
    def from_blocks(cls, blocks: Sequence[DiscreteLTI]) -> StackedLTI:
        """Stack one block per lane; blocks with fewer states are padded with inert ones
        (zero rows and columns), which changes no output."""
        first = blocks[0]
        for block in blocks:
            if (block.input_names, block.output_names, block.period_s) != (
                    first.input_names, first.output_names, first.period_s):
                raise ValueError("stacked blocks must share inputs, outputs and period")
        n = max(block.n_states for block in blocks)
        lanes, m, p = len(blocks), len(first.input_names), len(first.output_names)
        A, B = np.zeros((lanes, n, n)), np.zeros((lanes, n, m))
        C, D = np.zeros((lanes, p, n)), np.zeros((lanes, p, m))
        for lane, block in enumerate(blocks):
            size = block.n_states
            A[lane, :size, :size] = block.A
            B[lane, :size] = block.B
            C[lane, :, :size] = block.C
            D[lane] = block.D
        return cls(A, B, C, D, first.period_s, first.input_names, first.output_names)

    @property
    def lanes(self) -> int:
        """Number of lanes the matrices are stacked for."""
        return self.A.shape[0]

    @property
    def n_states(self) -> int:
        """States per lane."""
        return self.A.shape[1]

    def initial_state(self, lanes: int | None = None) -> np.ndarray:
        """A zero state (lanes, n); ``lanes`` must equal the stacked lanes when given."""
        if lanes is not None and lanes != self.lanes:
            raise ValueError(f"stacked for {self.lanes} lanes, asked for {lanes}")
        return np.zeros((self.lanes, self.n_states))

    def step(self, state: np.ndarray, inputs: np.ndarray) -> np.ndarray:
        """Outputs (lanes, p) for ``inputs`` (lanes, m); advances ``state`` in place."""
        stacked = self._stacked
        n = state.shape[1]
        stacked[:, :n, 0] = state
        stacked[:, n:, 0] = inputs
        result = (self._system @ stacked)[:, :, 0]
        p = result.shape[1] - n
        state[...] = result[:, p:]
        return result[:, :p]
