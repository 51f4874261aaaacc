"""A recorded Warp launch on the CPU, replayed without rebuilding its arguments.

A launch recorded with ``wp.launch(..., record_cmd=True)`` keeps its parameters, but on the
CPU device each ``Launch.launch()`` still packs them into a ctypes structure one field at a
time (Warp's ``invoke``): about 0.2 us per kernel argument, 5 us of the master node's kernel
of 24 arguments, where the kernel itself runs in about 1 us for one lane. The arguments of
the real-time ticks' launches never change (persistent buffers, constant structs), so
:class:`ReplayedLaunch` packs them once and then calls the kernel's entry point directly.

It uses the structure Warp itself built: the first call goes through ``Launch.launch()``,
which caches the argument structure's type on the kernel (``_invoke_cache``, as Warp 1.19
does); from the second call on, the replay calls the kernel's ``forward`` hook with that
structure filled once, exactly as ``invoke`` does. Where any of that is missing (another
Warp version, a CUDA device, a block launch, a backward pass), every call stays a plain
``Launch.launch()``: slower, never different.
"""

from __future__ import annotations

import ctypes
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np


class ReplayedLaunch:
    """``launch()`` runs the recorded ``command`` (a ``warp.Launch``) on its parameters."""

    __slots__ = ("command", "_replay", "_replayable", "_keep")

    def __init__(self, command: Any) -> None:
        self.command = command
        device = getattr(command, "device", None)
        self._replayable = bool(
            device is not None and getattr(device, "is_cpu", False)
            and getattr(command, "block_dim", 1) <= 1 and not getattr(command, "adjoint", True))
        self._replay: Callable[[], Any] | None = None
        self._keep: tuple = ()

    @property
    def replaying(self) -> bool:
        """True once calls go straight to the kernel's entry point."""
        return self._replay is not None

    def launch(self) -> None:
        """Run the kernel once over its recorded parameters."""
        replay = self._replay
        if replay is not None:
            replay()
            return
        self.command.launch()
        if self._replayable:
            self._prepare()

    def _prepare(self) -> None:
        """Fill Warp's own argument structure once (after Warp built and cached its type)."""
        self._replayable = False  # one try
        command = self.command
        params = getattr(command, "params", None)
        hooks = getattr(command, "hooks", None)
        cache = getattr(getattr(command, "kernel", None), "_invoke_cache", None)
        forward = getattr(hooks, "forward", None)
        if not params or forward is None or not isinstance(cache, dict):
            return
        cached = cache.get((tuple(type(p) for p in params[1:]), False))
        if not isinstance(cached, tuple) or len(cached) != 2:
            return
        args_type, fields = cached
        if len(fields) != len(params) - 1:
            return
        args = args_type()
        for (name, _), value in zip(fields, params[1:], strict=True):
            setattr(args, name, value)
        bounds_ref, args_ref = ctypes.byref(params[0]), ctypes.byref(args)
        self._keep = (params, args)  # the structures the references point into

        def replay() -> None:
            forward(bounds_ref, args_ref)

        self._replay = replay


def host_array(array: Any, dtype: Any) -> Any:
    """A Warp array on the CPU over ``array``'s memory (a C-contiguous numpy array, never
    copied), for a recorded launch to read and write in place; the caller keeps ``array``
    alive as long as the launch."""
    import warp as wp

    if not array.flags.c_contiguous:
        raise ValueError("a Warp launch can read only a C-contiguous array in place")
    return wp.array(array, dtype=dtype, device="cpu", copy=False)


def host_view(array: np.ndarray, dtype: Any) -> Any:
    """A Warp array on the CPU over ``array``'s memory as it is laid out (a strided view too,
    never copied); ValueError where Warp cannot read it in place (negative or unaligned
    strides). The caller keeps ``array`` alive as long as the launch."""
    import warp as wp

    itemsize = array.dtype.itemsize
    if any(stride <= 0 or stride % itemsize for stride in array.strides):
        raise ValueError("a Warp launch reads in place only positive, aligned strides")
    view = wp.array(array, dtype=dtype, device="cpu", copy=False)
    if view.ptr != array.ctypes.data:
        raise ValueError("Warp copied the array")
    return view


class InPlaceInputs:
    """The inputs of a recorded launch, fed either way, with the same result: copied into the
    launch's own ``buffers`` (the default), or, while a caller passes the very same array
    objects as on its call before, read in place from them by a second launch recorded over
    them (the lockstep's delay lines hand their persistent outputs every tick: copying them
    cost about 1 us an array).

    ``record(inputs)`` records the launch with ``inputs`` (Warp arrays, one per buffer, in
    order) as the inputs; ``warp_types``: each input's Warp dtype; ``castings``: each copy's
    numpy casting rule. Only arrays of each buffer's exact dtype and shape are read in place;
    the bound arrays are kept alive here, so an identity seen again is the same memory.
    """

    def __init__(self, buffers: Sequence[np.ndarray], warp_types: Sequence[Any],
                 castings: Sequence[str], record: Callable[[list[Any]], ReplayedLaunch]
                 ) -> None:
        self.buffers = tuple(buffers)
        self._warp_types = tuple(warp_types)
        self._castings = tuple(castings)
        self._record = record
        self._keep = [host_array(buffer, kind) for buffer, kind in
                      zip(self.buffers, self._warp_types, strict=True)]
        self._own = record(self._keep)
        self._bound: ReplayedLaunch | None = None
        self._bound_ids: tuple[int, ...] | None = None
        #: the bound arrays and their Warp views, held so their identities stay theirs
        self._bound_keep: tuple[Any, ...] = ()
        self._seen_ids: tuple[int, ...] | None = None
        self._seen_sources: tuple[np.ndarray, ...] = ()
        self._refused_ids: tuple[int, ...] | None = None
        self._last_in_place = False

    @property
    def in_place(self) -> bool:
        """Whether the last :meth:`launch` read its inputs in place."""
        return self._last_in_place

    def launch(self, sources: tuple[np.ndarray, ...]) -> None:
        """Run the kernel on ``sources`` (one array per buffer)."""
        ids = tuple(map(id, sources))
        bound = self._bound
        if bound is not None and ids == self._bound_ids:
            self._last_in_place = True
            bound.launch()
            return
        self._last_in_place = False
        for buffer, source, casting in zip(self.buffers, sources, self._castings, strict=True):
            np.copyto(buffer, source, casting=casting)  # type: ignore[arg-type]
        self._own.launch()
        if ids == self._seen_ids and ids != self._refused_ids:
            self._bind(sources, ids)
        else:
            self._seen_ids, self._seen_sources = ids, sources

    def _bind(self, sources: tuple[np.ndarray, ...], ids: tuple[int, ...]) -> None:
        """Record the launch over ``sources`` where each can be read in place."""
        try:
            for buffer, source in zip(self.buffers, sources, strict=True):
                if not (isinstance(source, np.ndarray) and source.dtype == buffer.dtype
                        and source.shape == buffer.shape):
                    raise ValueError("another dtype or shape")
            views = [host_view(source, kind) for source, kind in
                     zip(sources, self._warp_types, strict=True)]
        except ValueError:
            self._refused_ids = ids
            return
        self._bound = self._record(views)
        self._bound_ids, self._bound_keep = ids, (sources, views)


__all__ = ["InPlaceInputs", "ReplayedLaunch", "host_array", "host_view"]
