"""The master side, run on the rig PC: handle drivers (CAN or simulated rig) and the Ch
compensators that turn the operator's force into handle motion."""
