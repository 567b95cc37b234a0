"""Shared fixtures. Randomness is seeded per test; tolerances are named with units in each test module."""

from __future__ import annotations

import numpy as np
import pytest

import taplan


@pytest.fixture(scope="session")
def teleavatar() -> taplan.Robot:
    """The bundled TeleAvatar model (treat as read-only; build your own Robot to add frames)."""
    return taplan.Robot.teleavatar()


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20261121)
