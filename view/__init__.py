"""``haptic-view``: the live view of the tool and the clay in the browser (a separate
process; the real-time loops never serve HTTP)."""

from haptic.common.blas_threads import one_blas_thread

one_blas_thread()  # before any module of the package imports numpy
