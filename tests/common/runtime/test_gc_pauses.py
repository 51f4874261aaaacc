"""The garbage collector around the loops (common/runtime/gc_pauses.py): the frozen heap of a
block, with and without the collection first, inside another frozen block, and the pauses
timed while inside."""

from __future__ import annotations

import gc
import weakref

import pytest

from haptic.common.runtime.gc_pauses import GcPauses, frozen_heap


class _Cycle:
    """An object in a reference cycle: only the cyclic collector frees it."""

    def __init__(self) -> None:
        self.me = self


def _garbage_cycle() -> weakref.ref:
    """A weak reference to a new cycle that nothing else holds."""
    return weakref.ref(_Cycle())


pytestmark = pytest.mark.usefixtures("thawed_heap")


def test_the_collection_first_leaves_the_garbage_out_of_the_frozen_heap() -> None:
    garbage = _garbage_cycle()
    assert garbage() is not None
    with frozen_heap():
        assert gc.get_freeze_count() > 0
        assert garbage() is None
    assert gc.get_freeze_count() == 0


def test_without_the_collection_the_garbage_is_frozen_until_the_block_ends() -> None:
    garbage = _garbage_cycle()
    with frozen_heap(collect=False):
        gc.collect()  # a collection inside the block does not reach the frozen garbage
        assert garbage() is not None
    assert gc.get_freeze_count() == 0
    gc.collect()
    assert garbage() is None


def test_an_inner_block_freezes_what_is_new_and_leaves_the_thawing_to_the_outer_one() -> None:
    with frozen_heap(collect=False):
        outer = gc.get_freeze_count()
        new = [[] for _ in range(100)]  # tracked objects made inside the outer block
        with frozen_heap():
            assert gc.get_freeze_count() >= outer + len(new)
        assert gc.get_freeze_count() >= outer + len(new)  # the inner block did not thaw
    assert gc.get_freeze_count() == 0


def test_the_pauses_are_timed_inside_only() -> None:
    with GcPauses() as pauses:
        gc.collect(0)
        gc.collect(2)
    assert pauses.by_generation[0] >= 1 and pauses.by_generation[2] >= 1
    assert pauses.max_s > 0.0 and pauses.total_s >= pauses.max_s
    before = pauses.count
    gc.collect()
    assert pauses.count == before
    summary = pauses.summary()
    assert summary["gc_collections"] == before
    assert summary["gc_collections_by_generation"] == pauses.by_generation
