"""``haptic-slave-sim``: the slave alone on a scenario (an ideal master), the cut saved."""
