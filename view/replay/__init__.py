"""``haptic-replay``: recorded runs summarised, plotted, or played back into the live view."""
