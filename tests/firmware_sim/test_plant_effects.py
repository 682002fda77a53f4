"""Hidden physical effects of the plant: each off by default, each doing what its name says."""
from __future__ import annotations

import math

import numpy as np
import pytest

from spacearm.base.config.errors import ConfigError
from spacearm.firmware_sim.effects import DelayLine, TemperatureProfile, dead_zone, friction_torque, ft_sensor_error
from spacearm.firmware_sim.plant import ARCSEC, GRAVITY, JointModel, JointParams, Plant, PlantConfig, load_plant_config

EFFECT_FIELDS = ("viscous_friction", "coulomb_friction", "stribeck_friction", "backlash", "joint_stiffness",
                 "te_amplitude", "encoder_bias", "feedback_latency_cycles", "torque_limit", "gravity_torque",
                 "torque_noise")


def run(joint: JointModel, seconds: float, motor_torque: float = 0.0, h: float = 0.002) -> None:
    joint.brake_engaged = False
    joint.controller = lambda s, q, qd: motor_torque
    for _ in range(int(round(seconds / h))):
        joint.substep(1.0, h)


def test_every_effect_is_off_by_default():
    p = JointParams()
    assert all(getattr(p, name) == 0 for name in EFFECT_FIELDS)
    cfg = PlantConfig()
    assert cfg.ft.drift == cfg.ft.scale_error == cfg.ft.temp_coefficient == (0.0,) * 6
    assert cfg.geometry.thermal_expansion == 0.0 and cfg.payload.mass_error == 0.0


def test_coulomb_friction_holds_below_breakaway_and_slows_above():
    stuck = JointModel(JointParams(coulomb_friction=5.0))
    run(stuck, 1.0, motor_torque=0.04)             # 4 N m at the joint < 5 N m
    assert stuck.q == 0.0
    free = JointModel(JointParams())
    rubbing = JointModel(JointParams(coulomb_friction=5.0))
    run(free, 1.0, 0.1)
    run(rubbing, 1.0, 0.1)                          # 10 N m drive, 5 N m friction: half the acceleration
    assert rubbing.qd == pytest.approx(0.5 * free.qd, rel=0.02)


def test_stribeck_raises_the_breakaway_torque():
    joint = JointModel(JointParams(coulomb_friction=2.0, stribeck_friction=3.0))
    run(joint, 0.5, motor_torque=0.045)             # 4.5 N m < 2 + 3
    assert joint.q == 0.0
    run(joint, 0.5, motor_torque=0.055)
    assert joint.qd > 0.0
    assert friction_torque(1.0, 2.0, 0.0, 3.0, 0.01) == pytest.approx(2.0)
    assert friction_torque(1e-4, 2.0, 0.0, 3.0, 0.01) == pytest.approx(5.0, rel=1e-3)


def test_backlash_lets_the_motor_turn_before_the_link_follows():
    joint = JointModel(JointParams(backlash=0.01, link_inertia=5.0))
    run(joint, 0.05, motor_torque=0.05)
    assert joint.theta > 0.0 and joint.q == 0.0      # motor moving inside the play
    assert dead_zone(0.004, 0.01) == 0.0 and dead_zone(0.007, 0.01) == pytest.approx(0.002)


def test_joint_elasticity_deflects_by_torque_over_stiffness():
    k, load = 2.0e4, 40.0
    joint = JointModel(JointParams(joint_stiffness=k, joint_damping=500.0, gravity_torque=load, gravity_angle=0.0),
                       load_amplitude=load)
    # hold the motor side still, let the link settle against the gear's spring
    joint.brake_engaged = False
    joint.controller = lambda s, q, qd: None
    for _ in range(5000):
        joint.theta, joint.thetad = 0.0, 0.0
        joint.controller = lambda s, q, qd: 0.0
        joint._substep_two_mass(0.0, 0.001)
    assert joint.q == pytest.approx(-load / k, rel=0.05)


def test_transmission_error_ripples_the_link_angle():
    p = JointParams(te_amplitude=1e-4, te_harmonic=2.0, te_phase=0.3)
    joint = JointModel(p)
    run(joint, 0.5, motor_torque=0.1)
    expected = joint.theta + 1e-4 * math.sin(2.0 * 100.0 * joint.theta + 0.3)
    assert joint.q == pytest.approx(expected, abs=1e-12)
    assert joint.q != joint.theta


def test_encoder_bias_and_quantisation_are_in_the_reading_not_the_link():
    joint = JointModel(JointParams(encoder_bias=1e-3, resolver_arcsec=25.0), q=0.1)
    quantum = 25.0 * ARCSEC
    assert joint.q == 0.1
    assert joint.q_measured == pytest.approx(round(0.101 / quantum) * quantum)


def test_feedback_latency_reports_values_whole_cycles_late():
    plant = Plant.create(1, PlantConfig(joints=[JointParams(feedback_latency_cycles=2, resolver_arcsec=0.0)]))
    joint = plant.joints[0]
    joint.brake_engaged = False
    joint.controller = lambda s, q, qd: 0.5
    seen = []
    for _ in range(6):
        plant.step(0.02)
        seen.append((joint.q_measured, joint.q_reported))
    assert [r for _, r in seen[2:]] == [m for m, _ in seen[:4]]
    line = DelayLine(1, 0.0)
    line.push(5.0)
    assert line.output == 0.0


def test_torque_limit_saturates_the_motor_torque():
    joint = JointModel(JointParams(torque_limit=0.2))
    run(joint, 0.01, motor_torque=3.0)
    assert joint.motor_torque == 0.2


def test_gravity_load_and_payload_error_switch_with_gravity():
    params = JointParams(gravity_torque=10.0, payload_lever=1.5)
    ground = Plant.create(1, PlantConfig(joints=[params], payload={"mass_error": 2.0, "com_error": 0.1}))
    orbit = Plant.create(1, PlantConfig(joints=[params], gravity=False, payload={"mass_error": 2.0}))
    assert ground.joints[0].load_amplitude == pytest.approx(10.0 + 2.0 * GRAVITY * 1.6)
    assert orbit.joints[0].load_amplitude == 0.0
    joint = ground.joints[0]
    run(joint, 0.2)                                 # no drive torque: the load pulls the link down
    assert joint.q < -1e-3


def test_thermal_expansion_grows_the_arm_about_2mm_over_the_orbit_swing():
    cfg = PlantConfig(geometry={"thermal_expansion": 2.3e-5},
                      temperature={"reference": 20.0, "points": [[0.0, 20.0], [100.0, 63.0]]},
                      joints=[JointParams(initial_position=q) for q in (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)])
    plant = Plant.create(6, cfg)
    cold = plant.tool_pose()[:3, 3]
    plant.time = 100.0
    hot = plant.tool_pose()[:3, 3]
    strain = (np.linalg.norm(hot) - np.linalg.norm(cold)) / np.linalg.norm(cold)
    assert strain == pytest.approx(2.3e-5 * 43.0, rel=0.02)
    assert 2.0 * strain == pytest.approx(2.0e-3, rel=0.05)   # laser-ranger paper: about 2 mm on a 2 m arm
    assert TemperatureProfile(points=((0.0, 10.0), (10.0, 30.0))).at(5.0) == 20.0


def test_ft_bias_drift_scale_and_temperature_coefficient():
    out = ft_sensor_error([10.0, 0, 0, 0, 0, 0], t=100.0, temperature_delta=5.0, bias=[1.0] + [0] * 5,
                          drift=[0.01] + [0] * 5, scale_error=[0.02] + [0] * 5, temp_coefficient=[0.1] + [0] * 5)
    assert out[0] == pytest.approx(10.2 + 1.0 + 1.0 + 0.5)
    plant = Plant.create(0, PlantConfig(ft={"bias": [0.5, 0, 0, 0, 0, 0], "drift": [0.1, 0, 0, 0, 0, 0]}))
    plant.time = 10.0
    assert plant.ft_reading()[0] == pytest.approx(1.5)


def test_bad_effect_value_names_the_key(tmp_path):
    path = tmp_path / "p.toml"
    path.write_text("[[joints]]\nbacklash = 1.0\n")
    with pytest.raises(ConfigError, match=r"backlash"):
        load_plant_config(path)


def test_example_effect_plants_load():
    from pathlib import Path
    for path in (Path(__file__).resolve().parents[2] / "configs/plant/effects").glob("*.toml"):
        assert load_plant_config(path).joints
