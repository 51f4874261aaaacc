"""One BLAS thread per process, set before numpy loads its BLAS.

Every matrix here is small (a compensator's or the analysis's, tens of rows at most), so a
BLAS thread pool never speeds a product up; it costs CPU instead. OpenBLAS's worker threads
spin for a while after each call they took part in: during the synthesis and the margin
analysis (python-control and scipy) one worker kept a whole CPU busy beside the main thread.
On a machine with two CPUs that is half of them, taken from a latency sweep's other
process (its speed with and without the pool: docs/measurements/latency_sweep.md) and from a
real-time loop beside it.

:func:`one_blas_thread` sets the BLAS libraries' thread variables to 1 unless they are set
already (a user's own setting wins). The package's top-level modules call it on import,
which is before any of them imports numpy, so every program, its forked sweep workers and
the processes it starts get one thread. It has no effect in a process that loaded numpy
before it imported this package (a notebook that imported numpy first): there, set
``OPENBLAS_NUM_THREADS=1`` in the environment.
"""

from __future__ import annotations

import os

#: The variables OpenBLAS, MKL and BLIS read for their thread count when they load.
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS")


def one_blas_thread() -> None:
    """Set each of :data:`BLAS_THREAD_VARIABLES` to "1" where it is not set."""
    for name in BLAS_THREAD_VARIABLES:
        os.environ.setdefault(name, "1")
