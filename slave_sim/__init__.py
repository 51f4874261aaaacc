"""The slave side, run on the remote host: the virtual cutting tool, the Ct compensators and
the multi-block clay workpiece simulated with NVIDIA Warp kernels."""

from haptic.common.blas_threads import one_blas_thread

one_blas_thread()  # before any module of the package imports numpy
