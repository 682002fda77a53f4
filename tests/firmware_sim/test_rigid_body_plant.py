"""The simulated plant's coupled rigid-body dynamics: gravity and mass matrix agree with Pinocchio
read independently from the URDF, gravity is the plant file's vector, the payload hangs at the tool,
joints couple, brakes lock single joints, and an arm without inertials is refused by name."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from spacearm.base.config.arm import load_arm_config
from spacearm.base.config.errors import ConfigError
from spacearm.base.kinematics import KinematicData, jacobian
from spacearm.base.kinematics.forward import frames
from spacearm.firmware_sim.geometry import GeometryErrors
from spacearm.firmware_sim.plant import Plant, PlantConfig, PayloadParams
from spacearm.firmware_sim.rigid_body_config import RigidBodyParams
from tests.kinematics.urdf_reference import URDFS, PinocchioChain

G = (0.0, 0.0, -9.81)


def make_plant(arm: str, gravity=G, substeps: int = 10, **rigid) -> Plant:
    n = len(load_arm_config(f"configs/arm/{arm}.toml").joints)
    config = PlantConfig(substeps=substeps, geometry=GeometryErrors(arm=f"configs/arm/{arm}.toml"),
                         rigid_body=RigidBodyParams(gravity=gravity, **rigid))
    return Plant.create(n, config)


@pytest.mark.parametrize("arm", ["ur10", "panda"])
def test_gravity_and_mass_matrix_agree_with_pinocchio_from_the_urdf(arm) -> None:
    plant = make_plant(arm)
    dyn = plant.dynamics
    dyn.set_armature(np.zeros(dyn.nq))
    urdf, base, tip = URDFS[arm]
    ref = PinocchioChain(urdf, base, tip, list(plant.true_model.joint_names))
    for q in plant.true_model.random_configurations(30, np.random.default_rng(7)):
        assert np.abs(dyn.gravity(q) - ref.gravity(q, np.array(G))).max() < 1e-9     # N m
        assert np.abs(dyn.mass_matrix(q) - ref.mass_matrix(q)).max() < 1e-9         # kg m^2


def test_payload_at_the_tool_adds_its_weight_through_the_jacobian() -> None:
    bare, loaded = make_plant("ur10"), make_plant("ur10", payload_mass=5.0)
    model = bare.true_model
    q = model.random_configurations(1, np.random.default_rng(8))[0]
    J = jacobian(model, KinematicData(model), q)
    # generalized gravity is -J^T f for the weight f = m g at the tool point
    expected = -J[:3].T @ (5.0 * np.array(G))
    assert np.allclose(loaded.dynamics.gravity(q) - bare.dynamics.gravity(q), expected, atol=1e-9)


def release(plant: Plant) -> None:
    for joint in plant.joints:
        joint.brake_engaged = False


def test_on_orbit_an_unpowered_arm_at_rest_stays_at_rest() -> None:
    plant = make_plant("panda", gravity=(0.0, 0.0, 0.0))
    release(plant)
    q0 = plant.q_link.copy()
    for _ in range(50):
        plant.step(0.02)
    assert np.abs(plant.q_link - q0).max() < 1e-12


def test_on_the_ground_an_unpowered_arm_falls_as_minus_m_inverse_g() -> None:
    plant = make_plant("ur10", substeps=1)
    release(plant)
    q0 = plant.q_link.copy()
    h = 0.001
    plant.step(h)                        # one semi-implicit Euler step from rest: qd = h qdd
    qdd = np.array([j.qd for j in plant.joints]) / h
    rotor = plant.joints[0].params.motor_inertia * plant.joints[0].params.gear_ratio ** 2
    M = plant.dynamics.mass_matrix(q0)   # rotor inertias G^2 J_m on the diagonal (armature)
    assert np.allclose(plant.dynamics.model.armature, rotor)
    expected = np.linalg.solve(M, -plant.dynamics.gravity(q0))
    assert np.allclose(qdd, expected, rtol=1e-9, atol=1e-9)
    assert np.abs(expected[1]) > 0.1     # the shoulder really is loaded at home


def test_a_torque_on_one_joint_moves_the_others_and_brakes_lock_a_joint() -> None:
    plant = make_plant("panda", gravity=(0.0, 0.0, 0.0))
    release(plant)
    plant.joints[1].controller = lambda s, q, qd: 0.5          # motor side N m on joint 2
    plant.joints[3].brake_engaged = True                        # joint 4 held
    q0 = plant.q_link.copy()
    plant.step(0.02)
    moved = np.abs(plant.q_link - q0)
    assert moved[1] > 1e-6 and moved[3] == 0.0
    assert moved[0] > 1e-9 or moved[2] > 1e-9                  # inertial coupling through M(q)


def test_payload_mass_error_of_the_plant_file_adds_to_the_payload() -> None:
    config = PlantConfig(geometry=GeometryErrors(arm="configs/arm/ur10.toml"),
                         rigid_body=RigidBodyParams(gravity=G, payload_mass=2.0), payload=PayloadParams(mass_error=1.0))
    heavy, light = Plant.create(6, config), make_plant("ur10", payload_mass=3.0)
    q = np.full(6, 0.3)
    assert np.allclose(heavy.dynamics.gravity(q), light.dynamics.gravity(q), atol=1e-12)


def test_arm_without_inertials_is_refused_naming_the_file(tmp_path) -> None:
    text = Path("configs/arm/space_robot_6dof_laser.toml").read_text()
    bare = tmp_path / "bare_arm.toml"
    bare.write_text(text[:text.index("[[links]]")])
    config = PlantConfig(geometry=GeometryErrors(arm=str(bare)), rigid_body=RigidBodyParams())
    with pytest.raises(ConfigError, match=r"bare_arm.toml: no \[\[links\]\] inertials"):
        Plant.create(6, config)


def composite_body_reference(model, links, q: np.ndarray, g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gravity torques and mass matrix summed link by link from our own forward kinematics
    (link frames and joint axes), independent of the Pinocchio model the plant builds:
    g(q) = -sum m_k Jv_k^T g,  M(q) = sum m_k Jv_k^T Jv_k + Jw_k^T R_k I_k R_k^T Jw_k."""
    data = KinematicData(model)
    link_frames = frames(model, data, q)           # computes data.B: B[i]'s z is joint i's axis
    axes = [(data.B[i][:3, 2].copy(), data.B[i][:3, 3].copy()) for i in range(model.nq)]
    n = model.nq
    gravity, M = np.zeros(n), np.zeros((n, n))
    for k, link in enumerate(links):
        frame = link_frames[k + 1]
        R = frame[:3, :3]
        c = frame[:3, :3] @ np.array(link.com) + frame[:3, 3]
        ixx, ixy, ixz, iyy, iyz, izz = link.inertia
        inertia = R @ np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]]) @ R.T
        Jv, Jw = np.zeros((3, n)), np.zeros((3, n))
        for i in range(k + 1):
            z, p = axes[i]
            if model.joint_types[i] == "prismatic":
                Jv[:, i] = z
            else:
                Jv[:, i], Jw[:, i] = np.cross(z, c - p), z
        gravity -= link.mass * Jv.T @ g
        M += link.mass * Jv.T @ Jv + Jw.T @ inertia @ Jw
    return gravity, M


ARMS = sorted(p.stem for p in Path("configs/arm").glob("*.toml"))


@pytest.mark.parametrize("arm", ARMS)
def test_every_arm_in_the_repository_runs_the_rigid_body_plant(arm) -> None:
    """Each arm file has [[links]]; the plant's gravity and mass matrix (Pinocchio) agree with
    the link-by-link sums over our kinematics, and a released arm on orbit stays at rest."""
    plant = make_plant(arm, payload_mass=0.0)
    dyn = plant.dynamics
    dyn.set_armature(np.zeros(dyn.nq))
    links = load_arm_config(f"configs/arm/{arm}.toml").links
    g = np.array(G)
    for q in plant.true_model.random_configurations(10, np.random.default_rng(11)):
        gravity, M = composite_body_reference(plant.true_model, links, q, g)
        scale = max(1.0, np.abs(M).max())
        assert np.abs(dyn.gravity(q) - gravity).max() < 1e-9 * max(1.0, np.abs(gravity).max())   # N m
        assert np.abs(dyn.mass_matrix(q) - M).max() < 1e-9 * scale                               # kg m^2
    orbit = make_plant(arm, gravity=(0.0, 0.0, 0.0))
    release(orbit)
    q0 = orbit.q_link.copy()
    for _ in range(5):
        orbit.step(0.02)
    assert np.abs(orbit.q_link - q0).max() < 1e-12


def rigid_plant_with(arm: str, **joint) -> Plant:
    from spacearm.firmware_sim.plant import JointParams
    n = len(load_arm_config(f"configs/arm/{arm}.toml").joints)
    config = PlantConfig(geometry=GeometryErrors(arm=f"configs/arm/{arm}.toml"),
                         rigid_body=RigidBodyParams(gravity=(0.0, 0.0, 0.0)), joint=JointParams(**joint))
    plant = Plant.create(n, config)
    release(plant)
    return plant


def test_static_friction_holds_a_joint_against_a_small_torque() -> None:
    plant = rigid_plant_with("ur10", coulomb_friction=20.0)
    plant.joints[0].controller = lambda s, q, qd: 0.1     # 10 N m at the joint, below 20 N m
    q0 = plant.q_link.copy()
    for _ in range(10):
        plant.step(0.02)
    assert np.array_equal(plant.q_link, q0)
    plant.joints[0].controller = lambda s, q, qd: 0.5     # 50 N m breaks it loose
    plant.step(0.02)
    assert plant.q_link[0] > q0[0]


def test_elastic_gear_with_backlash_tracks_a_servo_and_stays_bounded() -> None:
    plant = rigid_plant_with("panda", joint_stiffness=2.0e4, backlash=0.002)
    target = plant.q_link.copy() + 0.05
    for i, joint in enumerate(plant.joints):
        joint.controller = (lambda t: lambda s, q, qd: 4.0 * (t - q) - 0.5 * qd)(target[i])
    for _ in range(200):                                    # 4 s
        plant.step(0.02)
    assert np.all(np.isfinite(plant.q_link))
    assert np.abs(plant.q_link - target).max() < 0.01     # within the play and the servo's droop
