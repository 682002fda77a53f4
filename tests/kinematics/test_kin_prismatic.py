"""Prismatic joints and N joints through FK, batched FK, Jacobian and IK; model/data pairing."""
from __future__ import annotations

import numpy as np
import pytest

from spacearm.base.kinematics import KinematicData, KinematicModel, fk, fk_batch, frames, jacobian, solve_ik
from spacearm.base.kinematics.arm_import import import_arm
from urdf_reference import URDFS


@pytest.fixture(scope="module")
def tiago() -> KinematicModel:
    """8 joints: a prismatic torso lift and a 7-joint arm."""
    return KinematicModel.from_config(import_arm(*URDFS["tiago"])[1])


def test_prismatic_joint_moves_the_tool_along_its_axis(tiago) -> None:
    data = KinematicData(tiago)
    q = tiago.q_home.copy()
    T0 = fk(tiago, data, q)
    q[0] += 0.1
    T1 = fk(tiago, data, q)
    axis = tiago.F[0][:3, 2]                      # the torso axis in the base frame
    assert np.allclose(T1[:3, 3] - T0[:3, 3], 0.1 * axis, atol=1e-12)
    assert np.allclose(T1[:3, :3], T0[:3, :3], atol=1e-12)


def test_batched_fk_and_frames_agree_with_single_fk(tiago) -> None:
    data = KinematicData(tiago)
    Q = tiago.random_configurations(50, np.random.default_rng(1))
    batch = fk_batch(tiago, Q)
    for q, T in zip(Q, batch):
        assert np.abs(T - fk(tiago, data, q)).max() < 1e-12
        assert np.abs(frames(tiago, data, q)[-1] - T).max() < 1e-12


def test_jacobian_matches_finite_differences_with_a_prismatic_joint(tiago) -> None:
    data = KinematicData(tiago)
    q = tiago.random_configurations(1, np.random.default_rng(2))[0]
    J = jacobian(tiago, data, q)
    h = 1e-7
    for i in range(tiago.nq):
        dq = np.zeros(tiago.nq)
        dq[i] = h
        Tp, Tm = fk(tiago, data, q + dq), fk(tiago, data, q - dq)
        assert np.allclose((Tp[:3, 3] - Tm[:3, 3]) / (2 * h), J[:3, i], atol=1e-6)
    assert np.array_equal(J[3:, 0], np.zeros(3))   # a slide turns nothing


def test_ik_reaches_a_pose_using_the_prismatic_joint(tiago) -> None:
    data = KinematicData(tiago)
    rng = np.random.default_rng(3)
    goal_q = tiago.random_configurations(1, rng, margin=0.05)[0]
    target = fk(tiago, data, goal_q)
    result = solve_ik(tiago, data, target, tiago.q_home)
    assert result.success, result.message
    assert np.abs(fk(tiago, data, result.q) - target).max() < 1e-6


def test_data_never_carries_another_models_geometry(models) -> None:
    nominal = models["oru_testbed_6dof"]
    perturbed = nominal.with_errors(da=np.full(6, 0.002), dtheta=np.full(6, 0.001))
    data = KinematicData(nominal)
    q = nominal.q_home
    T_nominal = fk(nominal, data, q)
    T_perturbed = fk(perturbed, data, q)        # nominal's data handed the perturbed model
    assert np.abs(T_perturbed - T_nominal).max() > 1e-4
    assert np.array_equal(T_perturbed, fk(perturbed, KinematicData(perturbed), q))
    assert np.array_equal(fk(nominal, data, q), T_nominal)


def test_data_for_another_joint_count_is_refused(models) -> None:
    data = KinematicData(models["oru_testbed_6dof"])
    with pytest.raises(ValueError, match="6 joints used with a 7-joint model"):
        fk(models["ssrms_7dof"], data, np.zeros(7))


def test_ik_on_a_seven_joint_arm_without_closed_form() -> None:
    """Panda (imported, 7 joints, no closed form): nearby seeds always converge."""
    from spacearm.base.kinematics import load_model
    from kin_reference import ARM_DIR
    panda = load_model(ARM_DIR / "panda.toml")
    data = KinematicData(panda)
    rng = np.random.default_rng(11)
    for q in panda.random_configurations(100, rng):
        seed = np.clip(q + rng.uniform(-0.3, 0.3, 7), panda.q_min, panda.q_max)
        result = solve_ik(panda, data, fk(panda, data, q), seed)
        assert result.success, result.message
