"""The simulated clay: the field, its Warp and NumPy kernels, the workpiece, its views and
rendering."""
