"""``haptic-view``: the live view of the tool and the clay in the browser (a separate
process; the real-time loops never serve HTTP)."""
