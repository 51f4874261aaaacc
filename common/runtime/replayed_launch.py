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
from collections.abc import Callable
from typing import Any


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


__all__ = ["ReplayedLaunch", "host_array"]
