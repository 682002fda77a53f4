"""Coupled rigid-body dynamics of the simulated arm (Pinocchio), with the drive trains on top.

Pinocchio is the field's standard for rigid-body algorithms (RNEA, CRBA, ABA in C++, a few
microseconds for a 7-joint arm); we build its model from our kinematic model (the plant's
true geometry) and the arm file's `[[links]]` inertials, so arms with and without a URDF go
the same way and the URDF importer's inertials are checked against Pinocchio's own URDF
parser in the tests. Each physics sub-step:

    (M(q) + diag(G^2 J_m)) qdd = tau_link - C(q, qd) qd - g(q) - tau_ext

with tau_link per joint from its drive (motor torque through the gear, less friction; the
rotor inertia G^2 J_m as armature) or, for an elastic/loose gear, the gear's coupling torque
(the motor side integrates on its own, as in the joint-level plant). Joints held by a brake,
jammed (stall fault) or in stiction are locked: the rest of the arm moves with them fixed
(the reduced system of the free joints). The old per-joint `gravity_torque` load is not
used here: gravity is the plant file's vector, and `link_inertia` is replaced by the links.
"""
from __future__ import annotations

import math
import operator
from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin

from spacearm.base.config.arm import ArmConfig
from spacearm.base.config.errors import ConfigError
from spacearm.base.config.inertia import LinkInertial
from spacearm.base.kinematics.model import KinematicModel
from spacearm.base.spatial import rotz
from spacearm.firmware_sim.effects import friction_torque, static_friction
from spacearm.firmware_sim.rigid_body_config import RigidBodyParams

if TYPE_CHECKING:
    from spacearm.firmware_sim.plant import JointModel, Plant

STICTION_SPEED = 1e-6   # rad/s: below this a joint with static friction may stick
# h * omega of the stiffest gear mode per integration step: semi-implicit Euler is stable below
# 2; 0.5 keeps the mode's damping close to the continuous one.
GEAR_STEP_LIMIT = 0.5


def _inertia(link: LinkInertial) -> pin.Inertia:
    ixx, ixy, ixz, iyy, iyz, izz = link.inertia
    I = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    return pin.Inertia(link.mass, np.array(link.com, dtype=float), I)


def build_pinocchio_model(model: KinematicModel, links: list[LinkInertial],
                          payload: pin.Inertia | None = None) -> pin.Model:
    """Pinocchio model of the chain: joint k placed at F_k Rz(theta_offset_k) in joint k-1's
    moving frame, link k's inertial in its D-H link frame (moving frame @ tails_k), the payload
    at the tool frame."""
    if len(links) != model.nq:
        raise ValueError(f"{len(links)} link inertials for {model.nq} joints")
    pm = pin.Model()
    pm.name = model.name
    parent = 0
    for k in range(model.nq):
        placement = pin.SE3(model.F[k] @ rotz(model.theta_offset[k]))
        joint = pin.JointModelPZ() if model.joint_types[k] == "prismatic" else pin.JointModelRZ()
        parent = pm.addJoint(parent, joint, placement, model.joint_names[k])
        pm.appendBodyToJoint(parent, _inertia(links[k]), pin.SE3(model.tails[k]))
    if payload is not None:
        pm.appendBodyToJoint(parent, payload, pin.SE3(model.F[model.nq]))
    return pm


class ArmDynamics:
    """M(q), C(q, qd) qd + g(q) and the locked-joint forward dynamics of one arm."""

    def __init__(self, pin_model: pin.Model, gravity: tuple[float, float, float]) -> None:
        self.model = pin_model
        self.model.gravity.linear = np.array(gravity, dtype=float)
        self.data = pin_model.createData()
        self.nq = pin_model.nq
        self._zero = np.zeros(self.nq)
        self._gear_omega: float | None = None   # set on the first step (needs the plant's joints)
        self.link_inertia = np.ones(self.nq)     # kg m^2, smallest M_ii seen (gear damping)
        self._params: tuple = ()                 # the joints' parameters joint_constants() was worked out for
        self._constants: tuple = ()

    def joint_constants(self, joints: list) -> tuple:
        """Per joint what a sub-step reads of its parameters: (elastic or loose gear, static
        friction, rotor inertia at the joint), worked out again only when a joint's parameters
        change (a sub-step read them 4 times per joint through calls: issue 35)."""
        params = tuple(joint.params for joint in joints)
        if len(params) != len(self._params) or not all(map(operator.is_, params, self._params)):
            self._constants = tuple((joint.two_mass, static_friction(p.coulomb_friction, p.stribeck_friction),
                                     p.motor_inertia * p.gear_ratio ** 2) for joint, p in zip(joints, params))
            self._params = params
        return self._constants

    def step_joints(self, plant: "Plant", s: float, h: float) -> None:
        """One physics sub-step of the plant's joints (see `substep`), split further when an
        elastic or loose gear would be too stiff for semi-implicit Euler at step h."""
        if self._gear_omega is None:
            self._gear_omega = self._stiffest_gear(plant)
        pieces = max(1, math.ceil(h * self._gear_omega / GEAR_STEP_LIMIT))
        for _ in range(pieces):
            substep(plant, self, s, h / pieces)

    def held_period(self, plant: "Plant", fractions, h: float) -> bool:
        """A whole SYNC period of sub-steps while every joint is braked or jammed behind a rigid
        gear (an arm at rest with its drives off): all are locked, so there is no dynamics to
        solve, and each joint runs its drive's servo on its standing position the period
        through (JointModel.stepper's held branch: the same servo calls and floats as
        substep() one sub-step at a time; a servo reads only its own joint). Issue 35: the
        sub-steps' arrays and per-joint calls were most of a resting Panda's simulator CPU.
        False, nothing changed: a joint is free or elastic."""
        joints = plant.joints
        for joint in joints:
            p = joint.params      # two_mass inline: every joint, every SYNC of a resting arm
            if not (joint.brake_engaged or joint.stalled) or p.joint_stiffness > 0.0 or p.backlash > 0.0:
                return False
        for joint in joints:
            joint.held_period(fractions, h)
        return True

    def _stiffest_gear(self, plant: "Plant", samples: int = 50) -> float:
        """rad/s of the fastest motor-link mode of the two-mass joints (0 if none), with the
        smallest link inertia the arm shows over random postures (M_ii without rotors)."""
        joints = [(i, j) for i, j in enumerate(plant.joints) if j.two_mass]
        if not joints:
            return 0.0
        model = plant.true_model
        saved = self.model.armature.copy()
        self.set_armature(np.zeros(self.nq))
        Q = model.random_configurations(samples, np.random.default_rng(0))
        smallest = np.min([np.diag(self.mass_matrix(q)) for q in Q], axis=0)
        self.set_armature(saved)
        self.link_inertia = np.maximum(smallest, 1e-9)
        omega = 0.0
        for i, joint in joints:
            p = joint.params
            stiffness = p.joint_stiffness or joint.RIGID_GEAR_STIFFNESS
            j_motor = p.motor_inertia * p.gear_ratio ** 2
            omega = max(omega, math.sqrt(stiffness * (1.0 / j_motor + 1.0 / max(smallest[i], 1e-9))))
        return omega

    def set_armature(self, armature: np.ndarray) -> None:
        self.model.armature = np.asarray(armature, dtype=float)

    def gravity(self, q: np.ndarray) -> np.ndarray:
        return pin.computeGeneralizedGravity(self.model, self.data, q).copy()

    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """M(q) with the armature on its diagonal (full symmetric copy)."""
        M = pin.crba(self.model, self.data, q)
        return np.triu(M) + np.triu(M, 1).T

    def bias(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """C(q, qd) qd + g(q)."""
        return pin.rnea(self.model, self.data, q, qd, self._zero)

    def acceleration(self, q: np.ndarray, qd: np.ndarray, tau: np.ndarray, locked: np.ndarray) -> np.ndarray:
        """qdd for joint torques tau with the `locked` joints held (their qdd = 0)."""
        if not locked.any():
            return pin.aba(self.model, self.data, q, qd, tau)
        qdd = np.zeros(self.nq)
        free = ~locked
        if free.any():
            M = self.mass_matrix(q)
            rhs = tau - self.bias(q, qd)
            qdd[free] = np.linalg.solve(M[np.ix_(free, free)], rhs[free])
        return qdd


def dynamics_for(plant_model: KinematicModel, arm: ArmConfig, arm_path: str, params: RigidBodyParams,
                 payload_mass_error: float) -> ArmDynamics:
    """The plant's arm dynamics: true geometry, the arm file's inertials, the payload."""
    if not arm.links:
        raise ConfigError(f"{arm_path}: no [[links]] inertials; the plant's [rigid_body] dynamics needs one "
                          f"per joint ({arm.arm.name}: {len(arm.joints)} joints)")
    mass = (params.payload_mass if params.payload_mass is not None else (arm.arm.payload or 0.0))
    mass = max(0.0, mass + payload_mass_error)
    payload = None
    if mass > 0.0:
        payload = pin.Inertia(mass, np.array(params.payload_com, dtype=float), np.diag(params.payload_inertia))
    return ArmDynamics(build_pinocchio_model(plant_model, list(arm.links), payload), params.gravity)


def substep(plant: "Plant", dynamics: ArmDynamics, s: float, h: float) -> None:
    """One physics sub-step of every joint with the coupled arm dynamics."""
    joints = plant.joints
    n = len(joints)
    # lists, not generators: a generator's resume per joint was a Python call each (issue 35)
    q = np.array([j.q for j in joints], dtype=float)
    qd = np.array([j.qd for j in joints], dtype=float)
    tau = np.empty(n)
    locked = np.zeros(n, dtype=bool)
    armature = np.empty(n)
    bias = None
    constants = dynamics.joint_constants(joints)
    for i, joint in enumerate(joints):
        drive = joint.drive_torque(s)
        p = joint.params
        two_mass, static, rotor = constants[i]
        if joint.brake_engaged or joint.stalled:
            locked[i] = True
            tau[i] = armature[i] = 0.0
            continue
        if two_mass:
            # the link inertia the gear sees is the arm's M_ii: the smallest over postures
            tau[i] = joint.advance_motor(drive, h, dynamics.link_inertia[i])
            armature[i] = 0.0
            friction_speed = joint.qd
        else:
            tau[i] = drive
            armature[i] = rotor
            friction_speed = joint.thetad
        tau[i] -= joint.external_torque
        if abs(friction_speed) > STICTION_SPEED or static == 0.0:
            tau[i] -= friction_torque(friction_speed, p.coulomb_friction, p.viscous_friction,
                                      p.stribeck_friction, p.stribeck_velocity)
        else:
            if bias is None:
                bias = dynamics.bias(q, qd)
            net = tau[i] - bias[i]   # what would accelerate the joint from rest
            if abs(net) <= static:
                locked[i] = True
            else:
                tau[i] -= math.copysign(static, net)
    if locked.all():
        for joint, (two_mass, _, _) in zip(joints, constants):
            joint.qd = 0.0
            if not two_mass:
                joint.thetad = 0.0
        return
    dynamics.set_armature(armature)
    qdd = dynamics.acceleration(q, qd, tau, locked)
    for i, joint in enumerate(joints):
        two_mass = constants[i][0]
        if locked[i]:
            joint.qd = 0.0
            if not two_mass:
                joint.thetad = 0.0
            continue
        if two_mass:
            joint.qd += qdd[i] * h
            joint.q += joint.qd * h
            continue
        joint.advance_stiff_gear(qdd[i], h)
