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


@pytest.fixture(scope="session")
def fr3_setup():
    """The real FR3 views and an error model with the board and camera frames started from them."""
    from spacearm.controller.calibration import fr3 as F
    data = F.load_fr3()
    kin = F.fr3_kinematics()
    W0, cam0 = F.initial_frames(kin, data, np.arange(len(data.Q)))
    return data, ErrorModel.from_kinematics(kin, world=W0, tool=cam0, world_prefix="board", tool_prefix="cam")
