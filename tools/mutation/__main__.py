"""``python3 -m tools.mutation``: the command line of :mod:`tools.mutation.cli`."""

import sys

from .cli import main

sys.exit(main())
