"""An imported arm's plant works as the diagnosis's nominal (issue 31): `arm import --plant`
names the arm file relative to the plant file wherever it ran, the loader finds it from
any working directory, and a replay of some joints of a coupled (rigid-body) arm simulates
the whole arm instead of refusing "the arm has 6 joints, the bus 1 joint drives"."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from typer.testing import CliRunner

from spacearm.console.main import app
from spacearm.offline.diagnosis.direct_sim import on_arm_drives, simulate
from spacearm.firmware_sim.plant import load_plant_config

REPO = Path(__file__).resolve().parents[2]
UR10 = REPO / "configs/urdf/ur10/ur10_robot.urdf"     # example-robot-data's UR10


def _import(tmp_path: Path) -> tuple[Path, Path, Path]:
    arm, bus, plant = tmp_path / "arms" / "ur10.toml", tmp_path / "arms" / "bus.toml", tmp_path / "plants" / "p.toml"
    arm.parent.mkdir()
    plant.parent.mkdir()
    res = CliRunner().invoke(app, ["arm", "import", str(UR10), "--base", "base_link", "--tip", "tool0", "--out",
                                   str(arm), "--bus", str(bus), "--plant", str(plant), "--gravity", "9.81"])
    assert res.exit_code == 0, res.output
    return arm, bus, plant


def test_the_plant_names_its_arm_relative_to_itself_and_loads_from_anywhere(tmp_path):
    arm, _, plant = _import(tmp_path)
    assert "arm = '../arms/ur10.toml'" in plant.read_text()
    here = os.getcwd()
    try:
        os.chdir(tmp_path / "arms")           # neither the project root nor the plant's folder
        config = load_plant_config(Path("..") / "plants" / "p.toml")
    finally:
        os.chdir(here)
    assert Path(config.geometry.arm_path()).resolve() == arm.resolve()
    assert config.rigid_body is not None


def test_a_replay_of_one_joint_of_a_coupled_arm_is_that_joint_of_the_whole_arm(tmp_path):
    arm, bus, plant = _import(tmp_path)
    config = on_arm_drives(load_plant_config(plant), arm, bus)
    t = np.arange(0.0, 0.6, 0.02)
    q_cmd = 0.1 * np.sin(2 * np.pi * t[:, None] / np.array([1.0, 1.2, 1.4, 1.6, 1.8, 2.0]))
    whole = simulate(config, q_cmd, 0.02)
    one = simulate(config, q_cmd, 0.02, joints=[2])
    assert one.q.shape == (len(t), 1)
    np.testing.assert_allclose(one.q[:, 0], whole.q[:, 2])
    np.testing.assert_allclose(one.tau[:, 0], whole.tau[:, 2])
