"""The cyclic garbage collector's pauses while the loop runs.

Python's collector stops every thread of the process while it runs (it holds the GIL), so a
collection that starts in any thread during a tick makes that tick as much longer. On the
programs' heaps (about 220,000 tracked objects after Warp, Zenoh and the synthesis have
loaded) a collection of the youngest generation takes tens of microseconds and one of the
middle generation up to milliseconds, longer than a tick. :class:`GcPauses` times each
collection between ``__enter__`` and ``__exit__`` (``gc.callbacks``), so a run's summary says
how many there were and the longest.

:func:`frozen_heap` collects once and freezes what is left before the loop (``gc.freeze``):
the start-up's objects are never scanned again, so a collection during the run looks at the
run's own young objects only. In ``haptic-session`` the one collection each loop met took
238-517 us before (the start-up's last objects still young; the runs since:
docs/measurements/programs_loops.md).
"""

from __future__ import annotations

import gc
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any


@contextmanager
def frozen_heap(collect: bool = True) -> Iterator[None]:
    """Collect everything, then freeze the survivors for the block (``gc.freeze``); they go
    back to the oldest generation after it (``gc.unfreeze``).

    ``collect=False`` freezes without collecting first: for a batch run that starts at once,
    where one full collection of a large heap costs as much as the ones it saves (the garbage
    frozen with the rest waits until the block ends). In a heap already frozen (an outer
    block, or a process that froze its own for good) the block freezes what is new and leaves
    the thawing to whoever froze first: thawing is all or nothing."""
    already_frozen = gc.get_freeze_count() > 0
    if collect:
        gc.collect()
    gc.freeze()
    try:
        yield
    finally:
        if not already_frozen:
            gc.unfreeze()


class GcPauses:
    """Context manager: counts and times the collections while inside (s, per generation)."""

    def __init__(self) -> None:
        self.by_generation = [0, 0, 0]
        self.total_s = 0.0
        self.max_s = 0.0
        self._started_ns: int | None = None

    def _callback(self, phase: str, info: dict[str, Any]) -> None:
        if phase == "start":
            self._started_ns = time.perf_counter_ns()
            return
        started = self._started_ns
        if started is None:  # entered in the middle of a collection
            return
        self._started_ns = None
        pause_s = (time.perf_counter_ns() - started) * 1e-9
        generation = int(info.get("generation", 2))
        self.by_generation[min(max(generation, 0), 2)] += 1
        self.total_s += pause_s
        if pause_s > self.max_s:
            self.max_s = pause_s

    def __enter__(self) -> GcPauses:
        gc.callbacks.append(self._callback)
        return self

    def __exit__(self, *_exc: object) -> None:
        if self._callback in gc.callbacks:
            gc.callbacks.remove(self._callback)
        self._started_ns = None

    @property
    def count(self) -> int:
        """Collections timed."""
        return sum(self.by_generation)

    def summary(self) -> dict[str, Any]:
        """The run summary's keys: collections per generation, their longest and total
        pause, s."""
        return {"gc_collections": self.count, "gc_collections_by_generation":
                list(self.by_generation), "gc_pause_max_s": self.max_s,
                "gc_pause_total_s": self.total_s}
