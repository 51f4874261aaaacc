"""``haptic-router``: the Zenoh router of the eclipse-zenoh wheel, for client-mode deployments."""
