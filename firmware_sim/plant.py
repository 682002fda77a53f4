"""The shared physical plant the simulated devices read and write.

Joint-level only for now: each joint is a motor driving a link through a harmonic-drive
reducer, with an optional brake. The drives' servo loops run inside ``Plant.step`` at a
sub-step rate through the ``controller`` callback each drive installs on its joint. The
force/torque sensor reads ``Plant.wrench``; the end-effector mechanism is ``Plant.ee``.

``Plant.step(dt)`` is called exactly once per SYNC by the simulator: nothing here runs on
a wall-clock timer. Every physics effect is a parameter of the plant TOML, off (zero) by
default, except the resolver quantisation (25 arcsec), which is the sensor's resolution.
"""
from __future__ import annotations

import math
import random
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from pydantic import BaseModel, ConfigDict, Field

from controller.config.loader import load_toml_model

ARCSEC = math.pi / (180.0 * 3600.0)


class Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class JointParams(Strict):
    motor_inertia: float = Field(default=3.0e-4, gt=0.0, le=1.0, description="kg m^2, motor side")
    link_inertia: float = Field(default=5.0, ge=0.0, le=1.0e6, description="kg m^2, joint side (constant)")
    gear_ratio: float = Field(default=100.0, ge=1.0, le=10000.0, description="harmonic drive reduction")
    gear_efficiency: float = Field(default=1.0, gt=0.0, le=1.0, description="off = 1.0")
    viscous_friction: float = Field(default=0.0, ge=0.0, le=1.0e4, description="N m s/rad at the joint; off = 0")
    coulomb_friction: float = Field(default=0.0, ge=0.0, le=1.0e4, description="N m at the joint; off = 0")
    resolver_arcsec: float = Field(default=25.0, ge=0.0, le=3600.0, description="output resolver quantum; 0 = ideal")
    servo_bandwidth_hz: float = Field(default=15.0, gt=0.0, le=200.0)
    servo_damping: float = Field(default=1.0, gt=0.0, le=5.0)
    initial_position: float = Field(default=0.0, ge=-20.0, le=20.0, description="rad")
    temperature: float = Field(default=25.0, ge=-100.0, le=200.0, description="degC drive temperature")


class EndEffectorParams(Strict):
    grip_close_time: float = Field(default=1.0, gt=0.0, le=60.0, description="s from open to closed")
    screw_speed: float = Field(default=5.0, gt=0.0, le=100.0, description="turns/s")
    screw_stiffness: float = Field(default=20.0, gt=0.0, le=1.0e4, description="N m per turn once seated")
    seat_turns: float = Field(default=5.6, ge=0.0, le=100.0, description="turns before the screw seats")
    target_present: bool = Field(default=True, description="an ORU interface is inside the grip")


class FtParams(Strict):
    noise_force: float = Field(default=0.0, ge=0.0, le=100.0, description="N rms; off = 0")
    noise_torque: float = Field(default=0.0, ge=0.0, le=100.0, description="N m rms; off = 0")
    bias: tuple[float, float, float, float, float, float] = (0.0,) * 6


class PlantConfig(Strict):
    substeps: int = Field(default=10, ge=1, le=1000, description="servo/physics sub-steps per SYNC period")
    joint: JointParams = JointParams()
    joints: list[JointParams] = Field(default_factory=list, description="per-joint overrides (in bus order)")
    end_effector: EndEffectorParams = EndEffectorParams()
    ft: FtParams = FtParams()
    seed: int = 0


def load_plant_config(path: str | Path | None) -> PlantConfig:
    return PlantConfig() if path is None else load_toml_model(path, PlantConfig)


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
    max_motor_torque: float = math.inf  # drive torque limit, N m motor side

    @property
    def effective_inertia(self) -> float:
        p = self.params
        return p.motor_inertia * p.gear_ratio ** 2 + p.link_inertia

    @property
    def q_measured(self) -> float:
        quantum = self.params.resolver_arcsec * ARCSEC
        if quantum <= 0.0:
            return self.q
        return round(self.q / quantum) * quantum

    def substep(self, s: float, h: float) -> None:
        tau_m = 0.0
        if self.controller is not None:
            tau_m = self.controller(s, self.q_measured, self.qd)
        tau_m = max(-self.max_motor_torque, min(self.max_motor_torque, tau_m))
        self.motor_torque = tau_m
        if self.brake_engaged or self.stalled:
            self.qd = 0.0
            return
        p = self.params
        tau = tau_m * p.gear_ratio * p.gear_efficiency - p.viscous_friction * self.qd - self.external_torque
        if p.coulomb_friction > 0.0:
            if abs(self.qd) > 1e-6:
                tau -= math.copysign(p.coulomb_friction, self.qd)
            elif abs(tau) <= p.coulomb_friction:
                tau = 0.0
            else:
                tau -= math.copysign(p.coulomb_friction, tau)
        self.qd += tau / self.effective_inertia * h   # semi-implicit Euler
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
        if self.jammed:
            return
        self.grip = min(1.0, max(0.0, self.grip + self.grip_speed * h))
        self.turns = max(0.0, self.turns + self.screw_speed * h)


@dataclass
class Plant:
    config: PlantConfig = field(default_factory=PlantConfig)
    joints: list[JointModel] = field(default_factory=list)
    ee: EndEffectorModel | None = None
    wrench: list[float] = field(default_factory=lambda: [0.0] * 6)   # at the F/T sensor, N and N m
    time: float = 0.0
    steps: int = 0

    @classmethod
    def create(cls, n_joints: int, config: PlantConfig | None = None) -> "Plant":
        config = config or PlantConfig()
        joints = []
        for i in range(n_joints):
            p = config.joints[i] if i < len(config.joints) else config.joint
            joints.append(JointModel(params=p, q=p.initial_position, temperature=p.temperature))
        plant = cls(config=config, joints=joints, ee=EndEffectorModel(config.end_effector))
        plant._rng = random.Random(config.seed)
        return plant

    def step(self, dt: float) -> None:
        n = self.config.substeps
        h = dt / n
        for k in range(n):
            s = (k + 1) / n
            for joint in self.joints:
                joint.substep(s, h)
            if self.ee is not None:
                self.ee.step(h)
        self.time += dt
        self.steps += 1

    def ft_reading(self) -> list[float]:
        """What the F/T sensor measures: the wrench plus (optional) bias and noise."""
        ft = self.config.ft
        rng = getattr(self, "_rng", random)
        out = []
        for i, w in enumerate(self.wrench):
            noise = ft.noise_force if i < 3 else ft.noise_torque
            out.append(w + ft.bias[i] + (rng.gauss(0.0, noise) if noise > 0.0 else 0.0))
        return out
