"""Shared fixtures: the paper's configuration and model, and a heap with nothing frozen."""

from __future__ import annotations

import gc
from collections.abc import Iterator

import pytest

from haptic.common.config import load_config
from haptic.common.model.teleop import TeleopModel, model_from_config


@pytest.fixture(scope="session")
def paper_config() -> dict:
    """The shipped defaults (the paper's values)."""
    return load_config()


@pytest.fixture(scope="session")
def paper_model(paper_config: dict) -> TeleopModel:
    """The paper's model, k = 1."""
    return model_from_config(paper_config)


@pytest.fixture
def thawed_heap() -> Iterator[None]:
    """Nothing frozen in the garbage collector during the test, as when a program starts (a
    mutation run's child freezes its preloaded heap for good); that freeze put back after."""
    frozen = gc.get_freeze_count()
    gc.unfreeze()
    yield
    if frozen:
        gc.freeze()
