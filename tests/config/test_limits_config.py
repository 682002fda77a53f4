"""Safety limits and approach tuning are configuration: defaults, overrides, clear errors."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from spacearm.base.config import ConfigError
from spacearm.base.config.arm import load_arm_config
from spacearm.controller.daemon.supervision import SupervisionLimits, Supervisor
from spacearm.controller.cycle import FindingCode, Measurement

ORU = Path(__file__).resolve().parents[2] / "configs" / "arm" / "oru_testbed_6dof.toml"


def with_tables(tmp_path: Path, tables: str) -> Path:
    path = tmp_path / "arm.toml"
    path.write_text(ORU.read_text() + "\n" + tables)
    return path


def test_defaults_are_the_commissioned_values():
    arm = load_arm_config(ORU)
    assert [j.drive.following_error for j in arm.joints] == [0.0175] * 6      # rad, 1 deg, per joint
    assert (arm.supervision.wrench_force_limit, arm.supervision.ft_jump_force) == (150.0, 80.0)
    assert arm.approach.lost_frames == 6


def test_an_override_reaches_the_supervisor(tmp_path):
    arm = load_arm_config(with_tables(tmp_path, "[supervision]\nwrench_force_limit = 60.0\n"))
    limits = SupervisionLimits(np.full(6, -3.0), np.full(6, 3.0), np.full(6, 1.0), settings=arm.supervision,
                               following_error=np.array([0.01, 0.005, 0.01, 0.01, 0.01, 0.01]))
    assert limits.wrench_force_limit == 60.0 and limits.ft_jump_force == 80.0
    sup = Supervisor(limits, [j.name for j in arm.joints])
    m = Measurement(0.0, 0, np.zeros(6), np.zeros(6), np.zeros(6), np.ones(6, bool), np.zeros(6, bool),
                    np.array([70.0, 0, 0, 0, 0, 0]))
    assert [f.code for f in sup.check(m, np.full(6, 0.004), moving=True)] == [FindingCode.FT_LIMIT]
    m2 = Measurement(0.0, 0, np.zeros(6), np.zeros(6), np.zeros(6), np.ones(6, bool), np.zeros(6, bool), np.zeros(6))
    findings = sup.check(m2, np.array([0.0, 0.006, 0, 0, 0, 0]), moving=True)
    assert [(f.code, f.joint) for f in findings] == [(FindingCode.FOLLOWING_ERROR, arm.joints[1].name)]


@pytest.mark.parametrize("tables, key", [
    ("[supervision]\nft_jump_force = 0\n", "supervision.ft_jump_force"),
    ("[supervision]\nwrench_force_limit = -1\n", "supervision.wrench_force_limit"),
    ("[supervision]\nfollowing_eror = 0.01\n", "supervision.following_eror"),
    ("[approach]\nlost_frames = 0\n", "approach.lost_frames"),
])
def test_a_bad_value_names_file_key_and_range(tmp_path, tables, key):
    path = with_tables(tmp_path, tables)
    with pytest.raises(ConfigError) as err:
        load_arm_config(path)
    message = str(err.value)
    assert str(path) in message and key in message and "\n" not in message.strip()
