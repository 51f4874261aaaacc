"""The simulated master rig: rig models and kernels, the emulated drive, the operator model and
haptic-rig-sim."""
