"""The shared physical plant the simulated devices read and write.

Joint-level only for now: each joint is a motor driving a link through a harmonic-drive
reducer, with an optional brake. The drives' servo loops run inside ``Plant.step`` at a
sub-step rate through the ``controller`` callback each drive installs on its joint. The
force/torque sensor reads ``Plant.wrench``; the end-effector mechanism is ``Plant.ee``.

``Plant.step(dt)`` is called exactly once per SYNC by the simulator: nothing here runs on
a wall-clock timer. Every physics effect is a parameter of the plant TOML, off (zero) by
default, except the position sensor's quantisation (25 arcsec resolver; 1 um linear encoder),
which is the sensor's resolution.

A joint is revolute (the default) or prismatic (``kind``): a prismatic joint is a linear
axis driven through a screw or rack, and every joint parameter is then in the axis' own SI
units (m, N, N s/m, kg, the gear ratio in motor rad per m of travel).
"""
from __future__ import annotations

import math
import random
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Literal, Protocol

import numpy as np
from pydantic import Field, model_validator

from spacearm.base.config.loader import StrictModel, load_toml_model
from spacearm.base.kinematics.forward import fk
from spacearm.base.kinematics.model import KinematicData, KinematicModel
from spacearm.firmware_sim.effects import (DelayLine, TemperatureProfile, dead_zone, friction_torque, ft_sensor_error,
                                  static_friction, transmission_error, transmission_error_slope)
from spacearm.firmware_sim.geometry import GeometryErrors
from spacearm.firmware_sim.laser_ranger import LaserTarget
from spacearm.firmware_sim.contact.config import ContactConfig
from spacearm.firmware_sim.rigid_body_config import RigidBodyParams
from spacearm.firmware_sim import simcore
from spacearm.firmware_sim.two_mass import two_mass_period

ARCSEC = math.pi / (180.0 * 3600.0)


# A linear axis' position sensor: 1 um is the step of a common magnetic linear encoder (e.g.
# RLS LM10 at 1 um resolution; optical scales reach 50 nm and below).
LINEAR_ENCODER_QUANTUM = 1.0e-6


class JointParams(StrictModel):
    """One joint's drive train and load. Units: revolute / prismatic (``kind``)."""
    kind: Literal["revolute", "prismatic"] = Field(
        default="revolute", description="prismatic: a linear axis (screw or rack); q in m, loads in N")
    motor_inertia: float = Field(default=3.0e-4, gt=0.0, le=1.0, description="kg m^2, motor side")
    link_inertia: float = Field(default=5.0, ge=0.0, le=1.0e6, description="kg m^2 (kg if prismatic), joint side "
                                                                            "(constant)")
    gear_ratio: float = Field(default=100.0, ge=1.0, le=10000.0,
                              description="harmonic drive reduction (motor rad per m of travel if prismatic: "
                                          "a 10 mm lead screw is 2 pi / 0.01 = 628)")
    gear_efficiency: float = Field(default=1.0, gt=0.0, le=1.0, description="off = 1.0")
    viscous_friction: float = Field(default=0.0, ge=0.0, le=1.0e4, description="N m s/rad (N s/m) at the joint; "
                                                                                "off = 0")
    coulomb_friction: float = Field(default=0.0, ge=0.0, le=1.0e4, description="N m (N) at the joint; off = 0")
    resolver_arcsec: float = Field(default=25.0, ge=0.0, le=3600.0,
                                   description="output resolver quantum of a revolute joint; 0 = ideal")
    encoder_quantum: float = Field(default=LINEAR_ENCODER_QUANTUM, ge=0.0, le=1.0e-2,
                                   description="m, linear encoder step of a prismatic joint (instead of "
                                               "resolver_arcsec); 0 = ideal")
    servo_bandwidth_hz: float = Field(default=15.0, gt=0.0, le=200.0)
    servo_damping: float = Field(default=1.0, gt=0.0, le=5.0)
    initial_position: float = Field(default=0.0, ge=-20.0, le=20.0, description="rad (m)")
    temperature: float = Field(default=25.0, ge=-100.0, le=200.0, description="degC drive temperature")
    # --- hidden physical effects (firmware_sim/effects), each off by default ---
    stribeck_friction: float = Field(default=0.0, ge=0.0, le=1.0e4, description="N m (N) static rise above "
                                                                                "Coulomb; off = 0")
    stribeck_velocity: float = Field(default=0.01, gt=0.0, le=10.0, description="rad/s (m/s), Stribeck decay speed")
    backlash: float = Field(default=0.0, ge=0.0, le=0.1, description="rad (m) total dead band in the gear; off = 0")
    joint_stiffness: float = Field(default=0.0, ge=0.0, le=1.0e6,
                                   description="N m/rad (N/m) motor-to-link elasticity; 0 = rigid (above 1e6 the "
                                               "2 ms physics sub-step is no longer stable)")
    joint_damping: float = Field(default=0.0, ge=0.0, le=1.0e5, description="N m s/rad (N s/m) across the elastic "
                                                                            "gear")
    te_amplitude: float = Field(default=0.0, ge=0.0, le=0.01, description="rad (m) transmission error")
    te_harmonic: float = Field(default=2.0, gt=0.0, le=10.0, description="cycles per wave-generator turn")
    te_phase: float = Field(default=0.0, ge=-7.0, le=7.0, description="rad")
    encoder_bias: float = Field(default=0.0, ge=-0.1, le=0.1, description="rad (m) added to the position reading")
    feedback_latency_cycles: int = Field(default=0, ge=0, le=20, description="SYNC cycles the reported values lag")
    torque_limit: float = Field(default=0.0, ge=0.0, le=1.0e4, description="N m motor side saturation; 0 = none")
    gravity_torque: float = Field(default=0.0, ge=0.0, le=1.0e5,
                                  description="revolute: N m load torque with the link horizontal (tau = G cos(q + "
                                              "angle)); prismatic: N, the weight on the axis' slide (force along "
                                              "the axis G cos(angle), whatever the position); off = 0")
    gravity_angle: float = Field(default=0.0, ge=-7.0, le=7.0,
                                 description="rad; revolute: where the load torque peaks; prismatic: the axis' "
                                             "tilt from the vertical (0: vertical with +q up, the whole weight "
                                             "pulls toward -q; pi/2: horizontal, no load)")
    payload_lever: float = Field(default=0.0, ge=-10.0, le=10.0, description="m from this joint axis to the payload "
                                                                             "(revolute only)")
    torque_noise: float = Field(default=0.0, ge=0.0, le=1.0e3, description="N m (N) rms, joint side, on the "
                                                                           "reported torque")

    @model_validator(mode="after")
    def _units_of_kind(self) -> "JointParams":
        defaults = type(self).model_fields
        if self.kind == "prismatic":
            if self.resolver_arcsec != defaults["resolver_arcsec"].default:
                raise ValueError("resolver_arcsec is a revolute joint's sensor: give a prismatic joint's position "
                                 "step as encoder_quantum (m)")
            if self.payload_lever != 0.0:
                raise ValueError("payload_lever is a revolute joint's lever arm: a prismatic joint carries the "
                                 "payload's weight along its axis without one")
        elif self.encoder_quantum != defaults["encoder_quantum"].default:
            raise ValueError('encoder_quantum is a linear encoder step (m): set kind = "prismatic" or give a '
                             "revolute joint's step as resolver_arcsec")
        return self

    @property
    def prismatic(self) -> bool:
        return self.kind == "prismatic"

    @property
    def position_quantum(self) -> float:
        """The position sensor's step in the joint's own unit (rad, or m if prismatic)."""
        return self.encoder_quantum if self.prismatic else self.resolver_arcsec * ARCSEC


class EndEffectorParams(StrictModel):
    grip_close_time: float = Field(default=1.0, gt=0.0, le=60.0, description="s from open to closed")
    screw_speed: float = Field(default=5.0, gt=0.0, le=100.0, description="turns/s")
    screw_stiffness: float = Field(default=20.0, gt=0.0, le=1.0e4, description="N m per turn once seated")
    seat_turns: float = Field(default=5.6, ge=0.0, le=100.0, description="turns before the screw seats")
    target_present: bool = Field(default=True, description="an ORU interface is inside the grip")


class FtParams(StrictModel):
    noise_force: float = Field(default=0.0, ge=0.0, le=100.0, description="N rms; off = 0")
    noise_torque: float = Field(default=0.0, ge=0.0, le=100.0, description="N m rms; off = 0")
    bias: tuple[float, float, float, float, float, float] = (0.0,) * 6
    drift: tuple[float, float, float, float, float, float] = Field(default=(0.0,) * 6, description="per s; off = 0")
    scale_error: tuple[float, float, float, float, float, float] = Field(default=(0.0,) * 6,
                                                                        description="fraction; off = 0")
    temp_coefficient: tuple[float, float, float, float, float, float] = Field(
        default=(0.0,) * 6, description="N (N m) per K from the profile's reference; off = 0")


class PayloadParams(StrictModel):
    mass_error: float = Field(default=0.0, ge=-1000.0, le=1000.0, description="kg more than the nominal payload")
    com_error: float = Field(default=0.0, ge=-1.0, le=1.0, description="m along each joint's payload lever")


class PlantConfig(StrictModel):
    substeps: int = Field(default=10, ge=1, le=1000, description="servo/physics sub-steps per SYNC period")
    joint: JointParams = JointParams()
    joints: list[JointParams] = Field(default_factory=list, description="per-joint overrides (in bus order)")
    end_effector: EndEffectorParams = EndEffectorParams()
    ft: FtParams = FtParams()
    gravity: bool = Field(default=True, description="joint load torques (gravity_torque, payload) act; false = orbit")
    payload: PayloadParams = PayloadParams()
    temperature: TemperatureProfile = Field(default_factory=TemperatureProfile,
                                            description="link/sensor temperature over the run (thermal effects)")
    geometry: GeometryErrors = GeometryErrors()
    laser: LaserTarget | None = None   # a laser ranger on the tool, served on a pty
    contact: ContactConfig | None = None   # the ORU cell's contact world (firmware_sim/contact)
    rigid_body: RigidBodyParams | None = None   # coupled arm dynamics (firmware_sim/rigid_body.py); None = per joint
    seed: int = 0

    def joint_params(self, j: int) -> JointParams:
        """Joint j's parameters (0-based): its own table, or the plant's default joint."""
        return self.joints[j] if j < len(self.joints) else self.joint


def load_plant_config(path: str | Path | None) -> PlantConfig:
    if path is None:
        return PlantConfig()
    config = load_toml_model(path, PlantConfig)
    arm = Path(config.geometry.arm)
    beside = Path(path).resolve().parent / arm
    if not arm.is_absolute() and beside.is_file():
        # a plant file written next to its arm file (spacearm arm import --plant) names it relative to
        # itself; the project's own plant files name theirs relative to the project root
        config = config.model_copy(update={"geometry": config.geometry.model_copy(update={"arm": str(beside)})})
    return config


class Environment(Protocol):
    """What the arm touches (contact world, gravity of held payloads).

    Called once per physics sub-step after the joints moved; sets ``plant.wrench`` (what the
    F/T sensor feels, sensor frame) and each joint's ``external_torque``."""

    def step(self, plant: "Plant", h: float) -> None: ...


# controller(s, q_measured, qd_measured) -> motor torque, s in (0, 1] through the SYNC period
Controller = Callable[[float, float, float], float]


@dataclass
class JointModel:
    params: JointParams
    q: float = 0.0
    qd: float = 0.0
    motor_torque: float = 0.0          # last applied, N m motor side
    brake_engaged: bool = True
    stalled: bool = False              # fault injection: mechanism jammed
    temperature: float = 25.0
    external_torque: float = 0.0       # N m at the joint from the environment (contact, later)
    controller: Controller | None = None
    # (the controller, a function giving its servo law for the whole period as the compiled
    # core takes it, or None when the core does not model its state): set by a drive
    period_servo: tuple | None = None
    max_motor_torque: float = math.inf  # drive torque limit, N m motor side
    load_amplitude: float = 0.0        # N m (N) gravity/payload load amplitude (set by Plant.create)
    theta: float = math.nan            # motor angle in joint units (gear output before play/error)
    thetad: float = 0.0
    feedback: DelayLine | None = None  # reported (q, qd) lag the physics by whole SYNC cycles
    noise_rng: random.Random | None = None
    torque_reported: float = 0.0       # motor torque as the drive reports it (with sensor noise), N m

    _quantum_of: JointParams | None = None    # q_measured's cache (class attributes, not fields)
    _quantum = 0.0

    # Stiffness standing in for a rigid gear when only backlash is set (rad play needs a
    # motor-side state); stable with the default 1 ms..2 ms sub-step.
    RIGID_GEAR_STIFFNESS = 1.0e5

    def __post_init__(self) -> None:
        if math.isnan(self.theta):
            self.theta = self.q
        lag = self.params.feedback_latency_cycles
        if lag > 0:
            self.feedback = DelayLine(lag, self.q_measured)
            self.feedback_velocity = DelayLine(lag, 0.0)

    @property
    def effective_inertia(self) -> float:
        p = self.params
        return p.motor_inertia * p.gear_ratio ** 2 + p.link_inertia

    @property
    def q_measured(self) -> float:
        p = self.params
        if p is not self._quantum_of:     # read a few times every SYNC: the step kept per params
            self._quantum_of, self._quantum = p, p.position_quantum
        q = self.q + p.encoder_bias
        quantum = self._quantum
        if quantum <= 0.0:
            return q
        return round(q / quantum) * quantum

    @property
    def q_reported(self) -> float:
        """Position the drive reports (TPDO): the resolver reading, late by the feedback latency."""
        return self.q_measured if self.feedback is None else self.feedback.output

    @property
    def qd_reported(self) -> float:
        return self.qd if self.feedback is None else self.feedback_velocity.output

    def readings(self) -> tuple[float, float, float]:
        """(q_measured, q_reported, qd_reported) in one call: a drive's SYNC end reads all three
        (issue 35), the encoder's reading worked out once."""
        q_measured = self.q_measured
        if self.feedback is None:
            return q_measured, q_measured, self.qd
        return q_measured, self.feedback.output, self.feedback_velocity.output

    def end_cycle(self) -> None:
        """Called once per SYNC period after the physics: feeds the feedback delay line."""
        if self.feedback is not None:
            self.feedback.push(self.q_measured)
            self.feedback_velocity.push(self.qd)
        noise = self.params.torque_noise
        self.torque_reported = self.motor_torque
        if noise > 0.0 and self.noise_rng is not None:
            self.torque_reported += self.noise_rng.gauss(0.0, noise / self.params.gear_ratio)

    @property
    def two_mass(self) -> bool:
        return self.params.joint_stiffness > 0.0 or self.params.backlash > 0.0

    def _friction(self, v: float) -> float:
        p = self.params
        return friction_torque(v, p.coulomb_friction, p.viscous_friction, p.stribeck_friction, p.stribeck_velocity)

    def _load(self) -> float:
        if self.load_amplitude == 0.0:
            return 0.0
        if self.params.prismatic:
            # a weight on a straight slide pulls along it the same at every position
            return self.load_amplitude * math.cos(self.params.gravity_angle)
        return self.load_amplitude * math.cos(self.q + self.params.gravity_angle)

    def drive_torque(self, s: float) -> float:
        """The drive's torque on the gear this sub-step, joint side: the servo callback's motor
        torque, saturated, stored as motor_torque. Velocity feedback comes from the motor
        encoder (collocated): with an elastic or loose gear, damping on the link speed alone
        would make the servo ring."""
        p = self.params
        tau_m = 0.0
        if self.controller is not None:
            # two_mass inlined: a coupled plant calls this for every joint every sub-step
            elastic = p.joint_stiffness > 0.0 or p.backlash > 0.0
            tau_m = self.controller(s, self.q_measured, self.thetad if elastic else self.qd)
        limit = self.max_motor_torque
        if p.torque_limit > 0.0:
            limit = min(limit, p.torque_limit)
        tau_m = max(-limit, min(limit, tau_m))
        self.motor_torque = tau_m
        return tau_m * p.gear_ratio * p.gear_efficiency

    def substep(self, s: float, h: float) -> None:
        self.substeps((s,), h)

    def substeps(self, fractions, h: float) -> None:
        """One sub-step of length h per fraction s of the SYNC period (the servo's
        interpolation point), in order. Plant.step hands a joint the whole period at once: a
        rigid gear is integrated on local variables with the constants read once, the same
        arithmetic in the same order as one substep() at a time (issue 35: 60 method calls
        and 80 property reads a cycle were a tenth of the simulator's CPU). Under a servo law
        the drive hands over for the whole period, a loose or elastic gear's period is
        one call (two_mass.py, or the compiled core's copy of it), and so, with the compiled core
        (simcore.py), is a rigid gear's."""
        servo = self.period_servo
        if servo is not None and servo[0] is self.controller and fractions:
            p = self.params          # two_mass inlined: every joint, every SYNC
            if p.joint_stiffness > 0.0 or p.backlash > 0.0:
                law = servo[1]()
                if law is not None:
                    self._two_mass_period(fractions, h, law, self._constants())
                    return
            elif simcore.core is not None:
                law = servo[1]()
                if law is not None and self._core_period(fractions, h, law, self._constants()):
                    return
        for _ in self.stepper(fractions, h, coupled=False):
            pass

    def _two_mass_period(self, fractions, h: float, law: tuple, constants: tuple) -> None:
        """stepper()'s two-mass period under the servo law `law` (as _core_period takes it): in
        the compiled core, or in Python where there is none or it leaves the period to Python."""
        held = self.brake_engaged or self.stalled
        args = (fractions, law[0], h, held, self.external_torque, self.q, self.qd, self.theta, self.thetad,
                self.motor_torque, law[1], law[2], law[3], law[4], constants)
        out = None if simcore.core is None else simcore.core.two_mass_period(*args)
        q, self.qd, theta, self.thetad, self.motor_torque, q_ref, v_ref = out or two_mass_period(*args)
        if not held:      # held, they stand still: the very objects kept (as stepper() leaves them)
            self.q, self.theta = q, theta
        law[5](q_ref, v_ref)

    def _core_period(self, fractions, h: float, law: tuple, constants: tuple) -> bool:
        """stepper()'s rigid-gear period in the compiled core, with the servo law `law` =
        (kind, q_start, q_end, v_ff, torque_ff, finish) and `constants` = _core_constants():
        finish(q_ref, v_ref) hands the drive its reference at the period's end. False: the
        core left this period to Python (a value Python's round() or cos() raises on),
        nothing changed."""
        held = self.brake_engaged or self.stalled
        out = simcore.core.rigid_period(fractions, law[0], h, held, self.external_torque, self.q, self.qd, self.theta,
                                        self.thetad, self.motor_torque, law[1], law[2], law[3], law[4], constants)
        if out is None:
            return False
        q, self.qd, theta, self.thetad, self.motor_torque, q_ref, v_ref = out
        if not held:      # held, they stand still: kept as they are (held_period: numpy scalars stay)
            self.q, self.theta = q, theta
        law[5](q_ref, v_ref)
        return True

    def held_period(self, fractions, h: float) -> None:
        """stepper()'s held branch (braked or jammed, rigid gear) for the whole period: the
        coupled plant's resting arm (rigid_body.ArmDynamics.held_period). In the compiled core
        where what it hands back is the Python path's types too: the core's numbers are floats,
        a coupled plant's positions numpy scalars. Held, the position and motor angle are not
        taken back (_core_period); with the drive powered off the servo's reference is the
        encoder's reading, a float in both paths where there is an encoder step (round() gives
        an int), and its torque 0.0 while the torque limit is above 0 (not the limit's object)."""
        servo = self.period_servo
        if simcore.core is not None and servo is not None and servo[0] is self.controller:
            law = servo[1]()
            if law is not None and law[0] == simcore.SERVO_OFF:
                constants = self._constants()
                if constants[1] > 0.0 and constants[2] > 0.0 and self._core_period(fractions, h, law, constants):
                    return
        for _ in self.stepper(fractions, h, coupled=False):
            pass

    _core_key = None      # _core_constants' cache (no annotation: class attributes, not dataclass fields)
    _core_values = ()

    def _constants(self) -> tuple:
        """_core_constants(), its usual answer (the cache holds) without the call: every joint,
        every SYNC."""
        key = self._core_key
        if key is not None and key[0] is self.params and key[1] == self.max_motor_torque \
                and key[2] == self.load_amplitude:
            return self._core_values
        return self._core_constants()

    def _core_constants(self) -> tuple:
        """What stepper() reads once a period and the servo law's gains, as the core takes them:
        worked out again only when the parameters, the drive's torque limit or the load
        amplitude changed (the same expressions as stepper() and advance_motor(), so the same
        floats). A loose or elastic gear's has advance_motor()'s constants after them (j_link,
        stiffness, j_motor, gear damping, half the play): two_mass_period() takes them (the
        core's and two_mass.py's), the core's rigid_period() refuses them."""
        key = (self.params, self.max_motor_torque, self.load_amplitude)
        if self._core_key != key:
            p = self.params
            limit = self.max_motor_torque
            if p.torque_limit > 0.0:
                limit = min(limit, p.torque_limit)
            amplitude = self.load_amplitude
            constant_load = p.prismatic or amplitude == 0.0
            load = self._load() if constant_load else 0.0    # else the first sub-step works it out
            values = (p.encoder_bias, p.position_quantum, limit, p.gear_ratio, p.gear_efficiency, amplitude,
                      p.gravity_angle, constant_load, load, p.coulomb_friction, p.viscous_friction,
                      p.stribeck_friction, p.stribeck_velocity, self.effective_inertia, p.te_amplitude,
                      p.te_harmonic, p.te_phase, p.servo_bandwidth_hz, p.servo_damping)
            if self.two_mass:
                j_link = max(p.link_inertia, 1e-3)
                values += (j_link,) + self._gear_coupling(j_link) + (0.5 * p.backlash,)
            self._core_values = values
            self._core_key = key
        return self._core_values

    def stepper(self, fractions, h: float, coupled: bool = True):
        """substeps() as a generator. `coupled` (a contact world acts between sub-steps): the
        state is written back and the generator yields after each sub-step, and reads the
        external torque again when resumed; the constants are still read once a period
        (issue 35: per-sub-step substep() calls were a fifth of an insertion trial's CPU)."""
        if self.two_mass:
            for s in fractions:
                drive = self.drive_torque(s)
                if self.brake_engaged or self.stalled:
                    self.qd = self.thetad = 0.0
                else:
                    self._substep_two_mass(drive, h)
                if coupled:
                    yield
            return
        p = self.params
        controller = self.controller
        bias, quantum = p.encoder_bias, p.position_quantum
        limit = self.max_motor_torque
        if p.torque_limit > 0.0:
            limit = min(limit, p.torque_limit)
        held = self.brake_engaged or self.stalled
        gear_ratio, efficiency, external = p.gear_ratio, p.gear_efficiency, self.external_torque
        amplitude, angle = self.load_amplitude, p.gravity_angle
        constant_load = p.prismatic or amplitude == 0.0
        load = self._load()
        coulomb, viscous, stribeck, stribeck_velocity = (p.coulomb_friction, p.viscous_friction,
                                                         p.stribeck_friction, p.stribeck_velocity)
        static = static_friction(coulomb, stribeck)
        inertia = self.effective_inertia
        te = (p.te_amplitude, p.te_harmonic, p.te_phase, gear_ratio) if p.te_amplitude > 0.0 else None
        q, qd, theta, thetad, tau_m = self.q, self.qd, self.theta, self.thetad, self.motor_torque
        if held:             # braked or jammed: the servo runs on a position that stands still
            x = q + bias
            q_measured = x if quantum <= 0.0 else round(x / quantum) * quantum
            for s in fractions:
                tau_m = 0.0 if controller is None else controller(s, q_measured, qd)
                tau_m = tau_m if tau_m < limit else limit      # min(limit, .), then max(-limit, .):
                tau_m = tau_m if tau_m > -limit else -limit    # the same picks, NaN and zeros alike
                qd = thetad = 0.0
                if coupled:
                    self.qd, self.thetad, self.motor_torque = qd, thetad, tau_m
                    yield
            self.qd, self.thetad, self.motor_torque = qd, thetad, tau_m
            return
        for s in fractions:
            # drive_torque() and q_measured, inlined on the locals
            tau_m = 0.0
            if controller is not None:
                x = q + bias
                tau_m = controller(s, x if quantum <= 0.0 else round(x / quantum) * quantum, qd)
            tau_m = tau_m if tau_m < limit else limit
            tau_m = tau_m if tau_m > -limit else -limit
            drive = tau_m * gear_ratio * efficiency
            if not constant_load:
                load = amplitude * math.cos(q + angle)
            tau = drive - external - load
            v = thetad
            if abs(v) > 1e-6 or static == 0.0:
                tau -= friction_torque(v, coulomb, viscous, stribeck, stribeck_velocity)
            elif abs(tau) <= static:
                tau = 0.0
                thetad = 0.0
            else:
                tau -= math.copysign(static, tau)
            # advance_stiff_gear(), inlined
            thetad += tau / inertia * h
            theta += thetad * h
            if te is not None:
                q = theta + transmission_error(theta, *te)
                qd = thetad * (1.0 + transmission_error_slope(theta, *te))
            else:
                q, qd = theta, thetad
            if coupled:
                self.q, self.qd, self.theta, self.thetad, self.motor_torque = q, qd, theta, thetad, tau_m
                yield
                external = self.external_torque
        self.q, self.qd, self.theta, self.thetad, self.motor_torque = q, qd, theta, thetad, tau_m

    def advance_stiff_gear(self, acceleration: float, h: float) -> None:
        """Semi-implicit Euler of motor and link moving together, plus transmission error."""
        p = self.params
        self.thetad += acceleration * h
        self.theta += self.thetad * h
        if p.te_amplitude > 0.0:
            args = (p.te_amplitude, p.te_harmonic, p.te_phase, p.gear_ratio)
            self.q = self.theta + transmission_error(self.theta, *args)
            self.qd = self.thetad * (1.0 + transmission_error_slope(self.theta, *args))
        else:
            self.q, self.qd = self.theta, self.thetad

    def advance_motor(self, drive: float, h: float, j_link: float) -> float:
        """Integrate the motor side of an elastic/loose gear; returns the coupling torque on
        the link. Damping defaults to 20 % of critical for the motor and `j_link`."""
        p = self.params
        stiffness, j_motor, damping = self._gear_coupling(j_link)
        out = self.theta + transmission_error(self.theta, p.te_amplitude, p.te_harmonic, p.te_phase, p.gear_ratio)
        deflection = dead_zone(out - self.q, p.backlash)
        coupling = stiffness * deflection + (damping * (self.thetad - self.qd) if deflection != 0.0 else 0.0)
        self.thetad += (drive - coupling) / j_motor * h
        self.theta += self.thetad * h
        return coupling

    def _gear_coupling(self, j_link: float) -> tuple[float, float, float]:
        """(stiffness, motor inertia at the joint, damping) of the gear between motor and link."""
        p = self.params
        stiffness = p.joint_stiffness or self.RIGID_GEAR_STIFFNESS
        j_motor = p.motor_inertia * p.gear_ratio ** 2
        damping = p.joint_damping or 0.2 * math.sqrt(stiffness * j_motor * j_link / (j_motor + j_link))
        return stiffness, j_motor, damping

    def _substep_two_mass(self, drive: float, h: float) -> None:
        """Motor and link as two inertias joined by the gear: stiffness, play, transmission error."""
        p = self.params
        j_link = max(p.link_inertia, 1e-3)
        coupling = self.advance_motor(drive, h, j_link)
        tau = coupling - self.external_torque - self._load()
        static = static_friction(p.coulomb_friction, p.stribeck_friction)
        if abs(self.qd) > 1e-6 or static == 0.0:
            tau -= self._friction(self.qd)
            self.qd += tau / j_link * h
        elif abs(tau) > static:
            self.qd += (tau - math.copysign(static, tau)) / j_link * h
        else:
            self.qd = 0.0
        self.q += self.qd * h


@dataclass
class EndEffectorModel:
    params: EndEffectorParams
    grip: float = 0.0          # 0 open .. 1 closed
    grip_speed: float = 0.0    # commanded, 1/s (+ closing)
    turns: float = 0.0         # screw turns (+ locking)
    screw_speed: float = 0.0   # commanded, turns/s
    jammed: bool = False       # fault injection

    @property
    def screw_torque(self) -> float:
        p = self.params
        if not p.target_present or self.grip < 1.0:
            return 0.0
        return max(0.0, self.turns - p.seat_turns) * p.screw_stiffness

    def step(self, h: float) -> None:
        self.steps(h, 1)

    def steps(self, h: float, n: int) -> None:
        """n sub-steps of length h: step() n times, on locals (issue 35: a call per sub-step was
        ten calls a SYNC for an end effector that is mostly at rest)."""
        if self.jammed:
            return
        grip, turns, grip_speed, screw_speed = self.grip, self.turns, self.grip_speed, self.screw_speed
        if n > 1 and grip_speed * h == 0.0 and screw_speed * h == 0.0:
            # at rest (nearly every SYNC): the first sub-step puts grip and turns in their ranges
            # as floats, where adding a zero and clamping again gives the very same floats
            n = 1
        for _ in range(n):
            grip = min(1.0, max(0.0, grip + grip_speed * h))
            turns = max(0.0, turns + screw_speed * h)
        self.grip, self.turns = grip, turns


@dataclass
class Plant:
    config: PlantConfig = field(default_factory=PlantConfig)
    joints: list[JointModel] = field(default_factory=list)
    ee: EndEffectorModel | None = None
    wrench: list[float] = field(default_factory=lambda: [0.0] * 6)   # at the F/T sensor, N and N m
    environment: Environment | None = None
    time: float = 0.0
    steps: int = 0
    dynamics: object | None = None   # spacearm.firmware_sim.rigid_body.ArmDynamics when [rigid_body] is on

    @classmethod
    def create(cls, n_joints: int, config: PlantConfig | None = None) -> "Plant":
        config = config or PlantConfig()
        joints = []
        for i in range(n_joints):
            p = config.joint_params(i)
            joints.append(JointModel(params=p, q=p.initial_position, temperature=p.temperature,
                                     load_amplitude=_load_amplitude(config, p),
                                     noise_rng=random.Random(config.seed * 1000 + i + 1)))
        plant = cls(config=config, joints=joints, ee=EndEffectorModel(config.end_effector))
        plant._rng = random.Random(config.seed)
        if config.contact is not None:
            from spacearm.firmware_sim.contact.world import build_contact_world
            plant.environment = build_contact_world(config.contact, plant)
        if config.rigid_body is not None:
            plant.dynamics = _rigid_body_dynamics(config, n_joints)
        return plant

    def step(self, dt: float) -> None:
        n = self.config.substeps
        h = dt / n
        fractions = [(k + 1) / n for k in range(n)]
        if self.environment is None:
            if self.dynamics is None:
                # no coupling between the joints within a period: each runs its sub-steps at once
                for joint in self.joints:
                    joint.substeps(fractions, h)
                apart = True
            else:     # an arm at rest (every joint held) has none either
                apart = self.dynamics.held_period(self, fractions, h)
            if apart:
                if self.ee is not None:
                    self.ee.steps(h, n)
                self._end_period(dt)
                return
        # coupled: every joint moves one sub-step, then the end effector and the environment
        steppers = None if self.dynamics is not None else [joint.stepper(fractions, h) for joint in self.joints]
        for s in fractions:
            if steppers is None:
                self.dynamics.step_joints(self, s, h)
            else:
                for stepper in steppers:
                    next(stepper)
            if self.ee is not None:
                self.ee.step(h)
            if self.environment is not None:
                self.environment.step(self, h)
        self._end_period(dt)

    def _end_period(self, dt: float) -> None:
        for joint in self.joints:
            joint.end_cycle()
        self.time += dt
        self.steps += 1

    @property
    def true_model(self) -> KinematicModel:
        """The arm as built (nominal arm file + the plant's hidden geometry errors)."""
        return self.config.geometry.true_model(self.config.temperature.delta(self.time))

    @property
    def q_link(self) -> np.ndarray:
        """True link-side joint angles, rad (not what the resolvers report)."""
        return np.array([j.q for j in self.joints])

    def tool_pose(self) -> np.ndarray:
        """True 4x4 base_T_tool of the arm now."""
        model = self.true_model
        # Read from the simulator's SYNC thread and from device threads (laser ranger, camera):
        # each thread gets its own kinematics scratch.
        local = self.__dict__.setdefault("_kin_local", threading.local())
        data = getattr(local, "data", None)
        # KinematicData precomputes from its model: a new one when the model changes (thermal growth)
        if data is None or data.nq != model.nq or getattr(local, "model", None) is not model:
            data = local.data = KinematicData(model)
            local.model = model
        return fk(model, data, self.q_link).copy()

    def ft_reading(self) -> list[float]:
        """What the F/T sensor measures: the wrench plus (optional) bias and noise."""
        ft = self.config.ft
        ideal = self.__dict__.get("_ideal_ft")
        if ideal is None or ideal[0] is not ft:      # frozen: judged once per configuration
            ideal = self._ideal_ft = (ft, _ideal_ft(ft))
        if ideal[1] and self.time - self.time == 0.0:
            # an ideal sensor (every SYNC of most plants): w * 1.0 + 0.0 + 0.0 * t + 0.0 * delta
            # below is w + 0.0 to the bit while t (and with it the delta) is finite, and no
            # noise draws from the random generator
            return [w + 0.0 for w in self.wrench]
        rng = getattr(self, "_rng", random)
        reading = ft_sensor_error(self.wrench, self.time, self.config.temperature.delta(self.time), ft.bias,
                                  ft.drift, ft.scale_error, ft.temp_coefficient)
        out = []
        for i, w in enumerate(reading):
            noise = ft.noise_force if i < 3 else ft.noise_torque
            out.append(w + (rng.gauss(0.0, noise) if noise > 0.0 else 0.0))
        return out


GRAVITY = 9.81


def _ideal_ft(ft: FtParams) -> bool:
    """No noise, and every error term +0.0 (a -0.0 would keep a reading's -0.0 sign)."""
    terms = ft.bias + ft.drift + ft.scale_error + ft.temp_coefficient
    return not ft.noise_force > 0.0 and not ft.noise_torque > 0.0 \
        and all(x == 0.0 and math.copysign(1.0, x) == 1.0 for x in terms)


def _rigid_body_dynamics(config: PlantConfig, n_joints: int):
    """The coupled dynamics of the plant's true arm (imports Pinocchio only when used)."""
    from spacearm.firmware_sim import rigid_body
    from spacearm.base.config.arm import load_arm_config
    from spacearm.base.config.errors import ConfigError
    path = config.geometry.arm_path()
    model = config.geometry.true_model()
    if model.nq != n_joints:
        raise ConfigError(f"{path}: the arm has {model.nq} joints, the bus {n_joints} joint drives")
    return rigid_body.dynamics_for(model, load_arm_config(path), str(path), config.rigid_body,
                                   config.payload.mass_error)


def _load_amplitude(config: PlantConfig, p: JointParams) -> float:
    """Gravity load amplitude on one joint: its own load plus the payload error (on a
    prismatic joint the payload rides on the slide: its whole weight, no lever)."""
    if not config.gravity:
        return 0.0
    payload = config.payload
    if p.prismatic:
        return p.gravity_torque + payload.mass_error * GRAVITY
    lever = p.payload_lever + (payload.com_error if p.payload_lever else 0.0)
    return p.gravity_torque + payload.mass_error * GRAVITY * lever
