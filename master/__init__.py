"""The master side, run on the rig PC: handle drivers (CAN or simulated rig) and the Ch
compensators that turn the operator's force into handle motion."""

from haptic.common.blas_threads import one_blas_thread

one_blas_thread()  # before any module of the package imports numpy
