"""Control laws of the teleoperation architectures beside the paper's scheme and TDPA (wave
variables, Lawrence's four-channel scheme, model-mediated teleoperation), the benchmark's task
environments and metrics: each law a numpy reference and a Warp kernel over lanes, numbers
only, no I/O (docs/architectures.md)."""
