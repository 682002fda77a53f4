"""IK: DLS round trips, closed-form solution sets, 7-DOF fixed-joint least-motion choice."""
from __future__ import annotations

import math

import numpy as np
import pytest

from spacearm.base.kinematics import (KinematicData, analytic_ik, analytic_solver, fk, fk_batch,
                                   ik_fixed_joint, pose_errors_batch, solve_dls, solve_ik,
                                   wrap_angle)

N_ROUND_TRIP = 10_000


def nearby_seeds(model, Q, rng):
    """q_true + a perturbation of 0.1-0.3 rad of random sign on every joint."""
    return Q + rng.uniform(0.1, 0.3, Q.shape) * rng.choice([-1.0, 1.0], Q.shape)


def test_ik_round_trip_10000_random_poses(arm, rng):
    model, data = arm
    Q = model.random_configurations(N_ROUND_TRIP, rng)
    targets = fk_batch(model, Q)
    seeds = nearby_seeds(model, Q, rng)
    sols = np.empty_like(Q)
    ok = np.zeros(N_ROUND_TRIP, dtype=bool)
    for k in range(N_ROUND_TRIP):
        r = solve_ik(model, data, targets[k], seeds[k])
        sols[k], ok[k] = r.q, r.success
    pos, ang = pose_errors_batch(targets, fk_batch(model, sols))
    good = ok & (pos <= 1e-6) & (ang <= 1e-6)
    rate = good.mean()
    print(f"\n{model.name}: IK success {rate:.4%} of {N_ROUND_TRIP}, "
          f"max error {pos[ok].max():.2e} m / {ang[ok].max():.2e} rad")
    assert rate >= 0.999
    assert np.all(sols >= model.q_min) and np.all(sols <= model.q_max)


def test_dls_reports_failure_for_unreachable_pose(arm):
    model, data = arm
    T = np.eye(4)
    T[:3, 3] = [2.0 * model.reach, 0.0, 0.0]
    r = solve_ik(model, data, T, model.q_home)
    assert not r.success and r.pos_error > 0.5 * model.reach
    assert isinstance(r.message, str) and r.message


def test_dls_on_perturbed_model_seeded_by_nominal(arm, rng):
    """A calibrated model has no exact closed form; the nominal one seeds the fallback."""
    model, _ = arm
    m = model.with_errors(dtheta=rng.normal(0, 3.5e-3, model.nq), da=rng.normal(0, 1e-3, model.nq),
                          dalpha=rng.normal(0, 3.5e-3, model.nq))
    data = KinematicData(m)
    Q = m.random_configurations(200, rng)
    T = fk_batch(m, Q)
    seeds = rng.uniform(m.q_min, m.q_max, Q.shape)  # far seeds force the fallback path
    ok = [solve_ik(m, data, T[k], seeds[k], analytic_model=model).success for k in range(200)]
    assert np.mean(ok) >= 0.95


@pytest.mark.parametrize("name", ["oru_testbed_6dof", "space_robot_6dof_laser"])
def test_analytic_solutions_consistent_with_fk(models, name, rng):
    m = models[name]
    data = KinematicData(m)
    counts = []
    for q in m.random_configurations(300, rng):
        T = fk(m, data, q)
        sols = analytic_ik(m, T, within_limits=False)
        counts.append(len(sols))
        assert 1 <= len(sols) <= 8
        pos, ang = pose_errors_batch(np.broadcast_to(T, (len(sols), 4, 4)), fk_batch(m, np.array(sols)))
        assert pos.max() < 1e-9 and ang.max() < 1e-9
        assert min(np.abs(wrap_angle(s - q)).max() for s in sols) < 1e-7  # q itself is found
        for s in analytic_ik(m, T):  # 2 pi copies within limits are solutions too
            assert m.within_limits(s)
    assert max(counts) == 8


@pytest.mark.parametrize("name", ["oru_testbed_6dof", "space_robot_6dof_laser"])
def test_analytic_set_is_complete(models, name, rng):
    """Every solution DLS finds from random seeds (limits off) is in the closed-form set."""
    m = models[name]
    data = KinematicData(m)
    for q in m.random_configurations(15, rng):
        T = fk(m, data, q)
        sols = analytic_ik(m, T, within_limits=False)
        for seed in rng.uniform(-math.pi, math.pi, (25, 6)):
            r = solve_dls(m, data, T, seed, respect_limits=False, max_iter=100)
            if r.success:
                assert min(np.abs(wrap_angle(s - r.q)).max() for s in sols) < 1e-6


def test_ssrms_analytic_with_theta2_fixed(models, rng):
    m = models["ssrms_7dof"]
    data = KinematicData(m)
    assert analytic_solver(m) is None  # redundant: needs a held joint
    for q in m.random_configurations(300, rng):
        T = fk(m, data, q)
        sols = analytic_ik(m, T, fixed={1: q[1]}, within_limits=False)
        assert 1 <= len(sols) <= 8
        assert all(s[1] == q[1] for s in sols)
        pos, ang = pose_errors_batch(np.broadcast_to(T, (len(sols), 4, 4)), fk_batch(m, np.array(sols)))
        assert pos.max() < 1e-9 and ang.max() < 1e-9
        assert min(np.abs(wrap_angle(s - q)).max() for s in sols) < 1e-7


def test_fixed_joint_ik_picks_least_motion(models, rng):
    """EKF paper 2.2: among all solutions (2 pi copies within +-300 deg too) the least motion."""
    m = models["ssrms_7dof"]
    data = KinematicData(m)
    same_branch = 0
    for _ in range(100):
        q_true = m.random_configurations(1, rng, margin=0.3)[0]
        q0 = q_true + rng.uniform(-0.3, 0.3, 7)
        T = fk(m, data, q_true)
        r = ik_fixed_joint(m, T, fixed_value=q_true[1], q0=q0, fixed_index=1)
        assert r.success and r.q[1] == q_true[1]
        assert r.pos_error < 1e-8 and r.rot_error < 1e-8
        every = analytic_ik(m, T, fixed={1: q_true[1]})
        assert len(every) >= 8  # +-300 deg ranges give extra 2 pi copies
        motion = [np.linalg.norm(s - q0) for s in every]
        assert np.linalg.norm(r.q - q0) == pytest.approx(min(motion))
        # q_true is one of the solutions, so the choice is at least as close as q_true;
        # usually it is q_true itself (another branch can be nearer near a singularity).
        assert np.linalg.norm(r.q - q0) <= np.linalg.norm(q_true - q0) + 1e-9
        same_branch += bool(np.allclose(r.q, q_true, atol=1e-7))
    assert same_branch >= 90


def test_fixed_joint_ik_chooses_the_wrapped_copy(models):
    """Near +300 deg the least-motion answer is the copy beyond +180 deg, not the wrapped one."""
    m = models["ssrms_7dof"]
    data = KinematicData(m)
    q_true = np.array([5.0, 0.3, -4.5, 1.0, 4.8, -5.1, 4.9])  # several joints past +-180 deg
    T = fk(m, data, q_true)
    r = ik_fixed_joint(m, T, fixed_value=0.3, q0=q_true + 0.05)
    np.testing.assert_allclose(r.q, q_true, atol=1e-7)
    assert np.abs(r.q).max() > math.pi


def test_fixed_joint_ik_on_calibrated_model(models, rng):
    """Model with parameter errors: nominal closed form seeds DLS with joint 2 locked."""
    nominal = models["ssrms_7dof"]
    m = nominal.with_errors(dtheta=rng.normal(0, 3.5e-3, 7), da=rng.normal(0, 2e-3, 7),
                            dd=rng.normal(0, 2e-3, 7), dalpha=rng.normal(0, 3.5e-3, 7))
    with pytest.raises(ValueError):
        ik_fixed_joint(m, np.eye(4), fixed_value=0.0, q0=np.zeros(7))
    data = KinematicData(m)
    for _ in range(20):
        q_true = m.random_configurations(1, rng, margin=0.3)[0]
        T = fk(m, data, q_true)
        q0 = q_true + rng.uniform(-0.2, 0.2, 7)
        r = ik_fixed_joint(m, T, fixed_value=q_true[1], q0=q0, nominal=nominal, data=data)
        assert r.success, r.message
        assert r.q[1] == q_true[1]
        assert r.pos_error <= 1e-6 and r.rot_error <= 1e-6
        assert np.linalg.norm(r.q - q0) <= np.linalg.norm(q_true - q0) + 1e-6


def test_locked_joint_stays_put(models, rng):
    m = models["ssrms_7dof"]
    data = KinematicData(m)
    q_true = m.random_configurations(1, rng, margin=0.5)[0]
    T = fk(m, data, q_true)
    seed = q_true + 0.1
    seed[1] = q_true[1]
    r = solve_dls(m, data, T, seed, locked=(1,))
    assert r.success and r.q[1] == q_true[1]
