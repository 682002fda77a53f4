import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from spacearm.controller.planning.errors import PlanningError
from spacearm.controller.planning.joint_move import JointLimits, JointMove

LIMITS = JointLimits(
    q_min=np.full(6, -3.0), q_max=np.full(6, 3.0),
    v_max=np.full(6, 0.1745), a_max=np.full(6, 0.349), j_max=np.full(6, 1.745))
PERIOD = 0.02


def sampled(move: JointMove):
    times = np.arange(0.0, move.duration + PERIOD, PERIOD)
    return np.array([move.sample(t).q for t in times]), np.array([move.sample(t).dq for t in times]), \
        np.array([move.sample(t).ddq for t in times])


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(-2.9, 2.9), min_size=12, max_size=12))
def test_move_ends_at_goal_within_velocity_and_acceleration_limits(values):
    start, goal = np.array(values[:6]), np.array(values[6:])
    move = JointMove.plan(start, goal, LIMITS)
    q, dq, ddq = sampled(move)
    np.testing.assert_allclose(move.sample(move.duration).q, goal, atol=1e-9)
    np.testing.assert_allclose(q[0], start, atol=1e-12)
    assert np.all(np.abs(dq) <= LIMITS.v_max * (1 + 1e-6))
    assert np.all(np.abs(ddq) <= LIMITS.a_max * (1 + 1e-6))


def test_joints_are_time_synchronised():
    move = JointMove.plan(np.zeros(6), np.array([1.0, 0.1, -0.5, 0.0, 0.2, 0.05]), LIMITS)
    # Every moving joint is still moving until shortly before the common end time.
    late = move.sample(move.duration - 0.2).dq
    moving = np.array([1.0, 0.1, -0.5, 0.0, 0.2, 0.05]) != 0
    assert np.all(np.abs(late[moving]) > 0)
    assert np.allclose(move.sample(move.duration).dq, 0.0, atol=1e-9)


def test_goal_outside_limits_is_refused_with_joint_named():
    goal = np.zeros(6)
    goal[3] = 3.5
    with pytest.raises(PlanningError, match=r"joint 4 goal 3.5000 rad is outside its limits"):
        JointMove.plan(np.zeros(6), goal, LIMITS)


@pytest.mark.parametrize("bad", [np.zeros(5), np.array([np.nan, 0, 0, 0, 0, 0])])
def test_malformed_goal_is_refused(bad):
    with pytest.raises(PlanningError):
        JointMove.plan(np.zeros(6), bad, LIMITS)


def test_slower_speed_scale_gives_longer_move():
    goal = np.full(6, 0.5)
    assert JointMove.plan(np.zeros(6), goal, LIMITS, speed_scale=0.5).duration > \
        1.5 * JointMove.plan(np.zeros(6), goal, LIMITS).duration
