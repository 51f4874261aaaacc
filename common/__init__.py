"""Shared core of haptic-teleop: configuration, the paper's two-port model, compensator
synthesis, discrete linear blocks and the delay-aware stability analysis. Everything here
works in SI units (m, N, s, N/m, N s/m) and does no I/O except reading configuration."""

from haptic.common.blas_threads import one_blas_thread

one_blas_thread()  # before any module of the package imports numpy
