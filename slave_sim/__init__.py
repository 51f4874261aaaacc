"""The slave side, run on the remote host: the virtual cutting tool, the Ct compensators and
the multi-block clay workpiece simulated with NVIDIA Warp kernels."""
