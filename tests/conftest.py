"""Shared fixtures: the paper's configuration and model."""

from __future__ import annotations

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
