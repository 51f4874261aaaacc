"""tools/ is scripts and a package outside the installed distribution: import
``tools.mutation`` from the repository once, for the tests here, without leaving the
repository's root on sys.path."""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

sys.path.insert(0, str(ROOT))
try:
    for _name in ("tools.mutation.cli", "tools.mutation.finder", "tools.mutation.changed"):
        importlib.import_module(_name)
finally:
    sys.path.remove(str(ROOT))
