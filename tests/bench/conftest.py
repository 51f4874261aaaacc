"""The benchmark tests' shared loader: bench/ is scripts, not a package."""

from __future__ import annotations

import importlib.util
from collections.abc import Callable
from pathlib import Path
from types import ModuleType

import pytest

BENCH_DIR = Path(__file__).resolve().parents[2] / "bench"


@pytest.fixture
def load_bench() -> Callable[[str], ModuleType]:
    """``load_bench("clay_bench")``: a fresh module of bench/clay_bench.py (fresh each call,
    so a test's monkeypatching stays its own)."""

    def load(name: str) -> ModuleType:
        spec = importlib.util.spec_from_file_location(name, BENCH_DIR / f"{name}.py")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module

    return load
