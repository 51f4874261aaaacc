"""The block-diagonal layout of a MIMO compensator, for kernels compiled with every loop of
constant length (slave_sim/node_kernels.py, master/node_kernels.py).

A compensator block made by :func:`haptic.common.model.lti.combine` is block diagonal: one
block of states per SISO path. Warp unrolls a loop of constant length and then knows every
index at compile time; a loop of run-time length over the dense matrices costs about ten
times as much on the CPU. So the kernels hold the matrices as equal blocks (smaller ones
padded with inert states) and are compiled once per layout.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class CompensatorLayout:
    """A compensator as ``blocks`` diagonal blocks of ``block_states`` states each (smaller
    blocks padded with inert states: their zeros add exactly nothing), which kernels are
    compiled for. The slave's four paths of four states: a quarter of the dense products."""

    blocks: int
    block_states: int

    @classmethod
    def of(cls, a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray
           ) -> tuple[CompensatorLayout, tuple[np.ndarray, ...], np.ndarray]:
        """The layout of ``a`` (L, n, n), ``b`` (L, n, m), ``c`` (L, p, n), ``d`` (L, p, m)
        (every lane's non-zeros), the matrices packed for it (``a`` (L, P, Q, Q), ``b``
        (L, P, Q, m), ``c`` (L, P, p, Q), ``d`` as it is) and, per packed state, the index of
        the state it holds (-1: padding)."""
        bounds = diagonal_blocks(np.any(a != 0.0, axis=0))
        q = max([end - start for start, end in bounds] + [1])
        lanes, p, m = a.shape[0], c.shape[1], b.shape[2]
        packed_a = np.zeros((lanes, len(bounds), q, q))
        packed_b = np.zeros((lanes, len(bounds), q, m))
        packed_c = np.zeros((lanes, len(bounds), p, q))
        state_of = np.full(len(bounds) * q, -1)
        for index, (start, end) in enumerate(bounds):
            size = end - start
            packed_a[:, index, :size, :size] = a[:, start:end, start:end]
            packed_b[:, index, :size] = b[:, start:end]
            packed_c[:, index, :, :size] = c[:, :, start:end]
            state_of[index * q:index * q + size] = np.arange(start, end)
        return (cls(max(len(bounds), 1), q),
                tuple(np.ascontiguousarray(x) for x in (packed_a, packed_b, packed_c, d)),
                state_of)


def diagonal_blocks(nonzero: np.ndarray) -> list[tuple[int, int]]:
    """The finest split of a square matrix's non-zero pattern ``nonzero`` (n, n) into
    diagonal blocks [start, end): nothing couples the states of two blocks."""
    n = nonzero.shape[0]
    bounds, start = [], 0
    for split in range(1, n + 1):
        if split == n or not (nonzero[start:split, split:].any()
                              or nonzero[split:, start:split].any()):
            bounds.append((start, split))
            start = split
    return bounds


__all__ = ["CompensatorLayout", "diagonal_blocks"]
