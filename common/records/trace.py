"""A small in-memory trace of a real-time run: every Nth sample into a preallocated array,
written as ``.npz`` at the end (off the hot path: a record is one row copy, no allocation)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np


class TraceRecorder:
    """Records ``columns`` (names with units, e.g. ``tool_force_x_N``) every ``every``-th call
    of :meth:`record`, up to ``capacity`` rows (later rows are dropped and counted)."""

    def __init__(self, columns: Sequence[str], every: int = 10, capacity: int = 200_000) -> None:
        if every < 1:
            raise ValueError(f"every must be >= 1 (got {every})")
        self.columns = tuple(columns)
        self.every = every
        self._data = np.full((capacity, len(self.columns)), np.nan)
        self.rows = 0
        self.dropped = 0
        self._calls = 0

    def due(self) -> bool:
        """Whether the next :meth:`record` call keeps its row (lets the caller skip building
        the row)."""
        return self._calls % self.every == 0

    def record(self, values: Sequence[float]) -> None:
        """Offer one sample (``len(columns)`` values); every ``every``-th is kept."""
        keep = self._calls % self.every == 0
        self._calls += 1
        if not keep:
            return
        if self.rows >= self._data.shape[0]:
            self.dropped += 1
            return
        self._data[self.rows] = values
        self.rows += 1

    def skip(self) -> None:
        """Count a sample without recording it (keeps the decimation phase)."""
        self._calls += 1

    def arrays(self) -> dict[str, np.ndarray]:
        """The recorded columns by name."""
        return {name: self._data[: self.rows, i].copy() for i, name in enumerate(self.columns)}

    def save(self, path: str | Path) -> Path:
        """Write the columns to ``path`` (``.npz``), creating parent folders."""
        target = Path(path)
        target.parent.mkdir(parents=True, exist_ok=True)
        np.savez(target, every=self.every, dropped=self.dropped, **self.arrays())
        return target
