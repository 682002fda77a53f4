"""Plant models and plant files."""
from __future__ import annotations

import math
from pathlib import Path

import pytest

from spacearm.base.config.errors import ConfigError
from spacearm.drivers.network import ArmCommand, ArmNetwork
from spacearm.firmware_sim.plant import ARCSEC, Plant, PlantConfig, load_plant_config
from spacearm.firmware_sim.runner import Simulator

PLANTS = Path(__file__).resolve().parents[2] / "firmware_sim" / "plants"


@pytest.mark.parametrize("name", ["ideal.toml", "realistic.toml"])
def test_plant_files_load(name):
    cfg = load_plant_config(PLANTS / name)
    assert cfg.joint.resolver_arcsec == 25.0


def test_plant_file_errors_name_the_key(tmp_path):
    p = tmp_path / "p.toml"
    p.write_text("[joint]\ngear_ratio = 0.5\n")
    with pytest.raises(ConfigError, match=r"joint\.gear_ratio"):
        load_plant_config(p)


def test_defaults_are_ideal_except_resolver():
    j = PlantConfig().joint
    assert j.viscous_friction == 0 and j.coulomb_friction == 0 and j.gear_efficiency == 1.0
    assert PlantConfig().ft.noise_force == 0


def test_joint_holds_with_brake_and_moves_with_torque():
    plant = Plant.create(1)
    j = plant.joints[0]
    j.controller = lambda s, q, qd: 1.0           # 1 N m motor torque
    plant.step(0.02)
    assert j.q == 0.0                              # brake engaged
    j.brake_engaged = False
    plant.step(0.02)
    acc = 1.0 * 100 / j.effective_inertia
    assert j.q == pytest.approx(0.5 * acc * 0.02 ** 2, rel=0.1)
    assert j.q_measured == pytest.approx(round(j.q / (25 * ARCSEC)) * 25 * ARCSEC)


def test_torque_limit_caps_motor_torque():
    plant = Plant.create(1)
    j = plant.joints[0]
    j.brake_engaged = False
    j.max_motor_torque = 0.5
    j.controller = lambda s, q, qd: 10.0
    plant.step(0.02)
    assert j.motor_torque == 0.5


def test_realistic_plant_still_tracks(vbus):
    sim = Simulator(vbus, "configs/bus/arm.toml", PLANTS / "realistic.toml").start()
    net = ArmNetwork(vbus)
    try:
        net.boot()
        net.enable_all()
        worst = 0.0
        for k in range(1, 51):
            s = net.cycle(ArmCommand(joint_positions=[0.05 * (1 - math.cos(math.pi * k / 50)) / 2] * 6))
            worst = max(worst, *(abs(j.following_error) for j in s.joints))
        assert worst < 0.01
        assert s.ft.force[2] == pytest.approx(1.1, abs=0.3)          # bias + noise, not tared
    finally:
        net.close()
        sim.stop()
