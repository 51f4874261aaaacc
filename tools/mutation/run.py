#!/usr/bin/env python3
"""Mutation testing of the configured modules: ``python3 tools/mutation/run.py --help``
(or ``python3 -m tools.mutation`` from the repository's root)."""

import sys
from pathlib import Path

if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
    from tools.mutation.cli import main

    sys.exit(main())
