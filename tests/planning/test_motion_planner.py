"""Cartesian moves on the ORU test-bed arm: straight, exact at the goal, refused when impossible."""
from pathlib import Path

import numpy as np
import pytest

from spacearm.base.kinematics.model import load_model
from spacearm.base.kinematics.pose_error import position_error, rotation_error
from spacearm.controller.planning.errors import PlanningError, PlanningFailure
from spacearm.base.spatial import rpy_to_matrix
from spacearm.controller.planning.motion_planner import MotionPlanner

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def planner():
    return MotionPlanner(load_model(ROOT / "configs/arm/oru_testbed_6dof.toml"), 0.02)


READY = np.array([-0.28806419791259463, 1.5707963267948966, -3.294079780986511, 1.9521648103310305,
                  -0.22888135613941607, 1.2827321288823015])


def working_posture(planner):
    # The "ready" posture of the arm file: well away from the home posture's wrist singularity.
    return READY.copy()


def test_tool_relative_move_ends_on_the_goal_and_stays_on_the_line(planner):
    q0 = working_posture(planner)
    start = planner.tool_pose(q0)
    plan = planner.pose_move(q0, np.array([0.05, -0.03, 0.04]), np.array([0.05, 0.0, -0.1]), frame="tool")
    offset = np.eye(4)
    offset[:3, :3] = rpy_to_matrix([0.05, 0.0, -0.1])
    offset[:3, 3] = [0.05, -0.03, 0.04]
    goal = start @ offset
    end = planner.tool_pose(plan.q[-1])
    assert position_error(goal, end) < 1e-5 and rotation_error(goal, end) < 1e-4
    direction = (goal[:3, 3] - start[:3, 3]) / np.linalg.norm(goal[:3, 3] - start[:3, 3])
    for q in plan.q[:: max(1, len(plan.q) // 20)]:
        p = planner.tool_pose(q)[:3, 3] - start[:3, 3]
        assert np.linalg.norm(p - p.dot(direction) * direction) < 2e-4  # within 0.2 mm of the line
    assert np.all(np.abs(plan.dq) <= planner.limits.v_max * 1.05)


def test_unreachable_pose_is_refused_before_any_motion(planner):
    with pytest.raises(PlanningError, match="beyond the arm's reach") as refused:
        planner.pose_move(working_posture(planner), np.array([5.0, 0, 0]), np.zeros(3))
    assert refused.value.kind is PlanningFailure.REACHABILITY


def test_jog_beyond_the_limit_is_refused(planner):
    q0 = np.array(planner.model.q_home)
    with pytest.raises(PlanningError, match="outside its limits") as refused:
        planner.jog(q0, 0, 3.5)
    assert refused.value.kind is PlanningFailure.JOINT_LIMITS


def test_move_through_the_singular_home_posture_is_refused(planner):
    # At home the wrist is singular: a sideways tool move needs unbounded joint rates.
    with pytest.raises(PlanningError, match="singularity|limit|not reached") as refused:
        planner.pose_move(np.array(planner.model.q_home), np.array([0.0, 0.05, 0.0]), np.zeros(3),
                          frame="tool")
    assert refused.value.kind in (PlanningFailure.JOINT_LIMITS, PlanningFailure.REACHABILITY)


def test_malformed_request_is_a_request_failure(planner):
    with pytest.raises(PlanningError) as refused:
        planner.pose_move(working_posture(planner), np.array([0.01, 0, 0]), np.zeros(3), frame="world")
    assert refused.value.kind is PlanningFailure.REQUEST
