"""Thin wrapper kept for old instructions: use the ``haptic-router`` entry point
(:mod:`haptic.common.wire.router.cli`)."""

import sys

from haptic.common.wire.router.cli import main

if __name__ == "__main__":
    sys.exit(main())
