"""Launching a whole session (haptic-session): both programs, one command."""
