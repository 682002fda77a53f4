"""Shared fixtures for the calibration tests (small, seeded, fast)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from spacearm.controller.calibration import ErrorModel, PlaneTarget, Problem
from spacearm.base.kinematics import load_model

ARM_DIR = Path(__file__).resolve().parents[2] / "configs" / "arm"


@pytest.fixture(scope="session")
def laser_kin():
    return load_model(ARM_DIR / "space_robot_6dof_laser.toml")


@pytest.fixture(scope="session")
def ssrms_kin():
    return load_model(ARM_DIR / "ssrms_7dof.toml")


@pytest.fixture(scope="session")
def laser_em(laser_kin):
    return ErrorModel.from_kinematics(laser_kin)


@pytest.fixture(scope="session")
def ssrms_em(ssrms_kin):
    return ErrorModel.from_kinematics(ssrms_kin)


@pytest.fixture(scope="session")
def paper_plane():
    return PlaneTarget((0.0, 1.0, 4.6), -0.69)


@pytest.fixture(scope="session")
def laser_setup():
    from spacearm.controller.calibration import study_laser
    return study_laser.setup()


def laser_problem(em, plane, Q, measured, free, sigma=2e-4):
    return Problem(em, "plane", Q, measured, free, plane=plane, sigma=np.array([sigma]))
