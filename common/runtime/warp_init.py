"""Warp's start-up for the programs: once, without its banner on stdout, and on a host
without the NVIDIA CUDA driver without the warning Warp's native library prints there.

That warning ("Warp CUDA warning: Could not find or load the NVIDIA CUDA driver") comes from
the native ``wp_init`` through ``fprintf(stderr, ...)`` whenever ``libcuda`` does not load;
no ``warp.config`` setting turns it off. On such a host Warp runs every kernel on its CPU
device, which is what the programs then use (each says where its clay or kernels run), so
:func:`init_warp` initialises Warp there with file descriptor 2 pointed at /dev/null.
"""

from __future__ import annotations

import ctypes
import os
import sys

#: The CUDA driver library as Warp's native code loads it on Linux (in this order).
CUDA_DRIVER_LIBRARIES = ("libcuda.so", "libcuda.so.1")


def cuda_driver_loads() -> bool:
    """Whether the NVIDIA CUDA driver library loads in this process (True off Linux, where
    the names differ: nothing is silenced there)."""
    if not sys.platform.startswith("linux"):
        return True
    for name in CUDA_DRIVER_LIBRARIES:
        try:
            ctypes.CDLL(name)
        except OSError:
            continue
        return True
    return False


def init_warp() -> None:
    """Set Warp's log level to warnings, so no start-up banner reaches stdout; on a host
    without the CUDA driver also initialise Warp now (a no-op when it already is) with its
    native warning about that silenced. Where the driver loads, Warp initialises where the
    program first uses it, as it would without this call. Call it before the first Warp
    array or launch, in the main thread, before the program's other threads start (stderr is
    redirected for the call)."""
    import warp as wp

    wp.config.log_level = wp.LOG_WARNING
    if cuda_driver_loads():
        return
    sys.stderr.flush()
    saved = os.dup(2)
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 2)
        wp.init()
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(devnull)
