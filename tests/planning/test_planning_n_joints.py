"""Planning on arms beyond the papers' three: 7 joints (Panda) and a prismatic torso (TIAGo, 8)."""
from pathlib import Path

import numpy as np
import pytest

from spacearm.base.config.arm import load_arm_config
from spacearm.base.kinematics.arm_import import import_arm
from spacearm.base.kinematics.model import KinematicModel, load_model
from spacearm.base.kinematics.pose_error import position_error, rotation_error
from spacearm.controller.planning.motion_planner import MotionPlanner

ROOT = Path(__file__).resolve().parents[2]
TIAGO = (ROOT / "configs/urdf/tiago/tiago_no_hand.urdf", "base_link", "arm_tool_link")


@pytest.fixture(scope="module", params=["panda", "tiago"])
def arm(request):
    if request.param == "tiago":
        data, config = import_arm(*TIAGO)
        return MotionPlanner(KinematicModel.from_config(config), 0.02), np.array(data["postures"]["ready"])
    path = ROOT / "configs/arm/panda.toml"
    return MotionPlanner(load_model(path), 0.02), np.array(load_arm_config(path).postures["ready"])


def test_joint_move_respects_each_joints_own_limits(arm) -> None:
    planner, ready = arm
    move = planner.joint_move(planner.model.q_home, ready)
    t = np.arange(0.0, move.duration + 0.02, 0.02)
    q = np.array([move.sample(ti).q for ti in t])
    dq = np.array([move.sample(ti).dq for ti in t])
    assert np.allclose(q[-1], ready, atol=1e-9)
    assert np.all(np.abs(dq) <= planner.limits.v_max * (1 + 1e-6))


def test_cartesian_move_ends_on_the_goal(arm) -> None:
    planner, ready = arm
    start = planner.tool_pose(ready)
    plan = planner.pose_move(ready, np.array([0.0, 0.0, 0.05]), np.zeros(3), frame="tool")
    goal = start.copy()
    goal[:3, 3] += start[:3, 2] * 0.05
    end = planner.tool_pose(plan.q[-1])
    assert position_error(goal, end) < 1e-5 and rotation_error(goal, end) < 1e-4
    assert np.all(np.abs(plan.dq) <= planner.limits.v_max * 1.05)
    assert planner.model.within_limits(plan.q[-1], tol=1e-9)
