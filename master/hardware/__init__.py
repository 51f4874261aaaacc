"""The master's hardware interface and its CAN backends (CiA 402 drives, force sensor, bus
load, the unix-datagram CAN bus); dbc/ and eds/."""
