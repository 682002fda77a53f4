"""Shared fixtures for the kinematics tests: the three arm models from configs/arm."""
from __future__ import annotations

import numpy as np
import pytest

from spacearm.base.kinematics import KinematicData, load_model
from kin_reference import ARM_DIR, ARMS


@pytest.fixture(scope="session", params=ARMS)
def arm(request):
    """(model, data) for each arm file."""
    model = load_model(ARM_DIR / f"{request.param}.toml")
    return model, KinematicData(model)


@pytest.fixture(scope="session")
def models():
    return {name: load_model(ARM_DIR / f"{name}.toml") for name in ARMS}


@pytest.fixture()
def rng():
    return np.random.default_rng(20261122)
