"""Thin wrapper kept for old instructions: use the ``haptic-router`` entry point
(:mod:`haptic.common.router`)."""

import sys

from haptic.common.router import main

if __name__ == "__main__":
    sys.exit(main())
