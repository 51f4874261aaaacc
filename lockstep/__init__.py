"""The lockstep simulator: master and slave nodes, the simulated rig and the operator model in
one process, joined by exact sample delay lines; deterministic, faster than real time, many
independent lanes at once. It composes both sides, so it lives outside haptic.common."""

from haptic.common.blas_threads import one_blas_thread

one_blas_thread()  # before any module of the package imports numpy
