"""Arm files load, and every kind of bad file gives one clear error naming file and key."""
from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import pytest

from spacearm.base.config import ConfigError
from spacearm.base.config.arm import load_arm_config

ROOT = Path(__file__).resolve().parents[2]
ARMS = ROOT / "configs" / "arm"
ORU = ARMS / "oru_testbed_6dof.toml"


def test_the_three_paper_arms_load_with_their_tables():
    oru = load_arm_config(ORU)
    assert oru.arm.convention == "modified"
    assert [j.d for j in oru.joints] == pytest.approx([0, 0.17885, 0, -0.174, 0, 0])
    assert [j.a for j in oru.joints] == pytest.approx([0, 0, 0, 0.560, 0.385, 0])
    assert [math.degrees(j.home) for j in oru.joints] == pytest.approx([0, 90, -90, 0, -90, 0])
    assert oru.tool.dh.d == pytest.approx(0.46615)
    assert oru.sensors.resolver_accuracy == pytest.approx(math.radians(25 / 3600))

    laser = load_arm_config(ARMS / "space_robot_6dof_laser.toml")
    assert laser.arm.convention == "standard"
    assert [j.beta is not None for j in laser.joints] == [False, True, False, False, False, True]
    assert laser.plane.normal == (0.0, 1.0, 4.6) and laser.plane.offset == -0.69

    ssrms = load_arm_config(ARMS / "ssrms_7dof.toml")
    assert len(ssrms.joints) == 7
    assert all(j.limits.upper == pytest.approx(math.radians(300)) for j in ssrms.joints)
    assert ssrms.base.dh.theta == pytest.approx(-math.pi / 2)


def write_variant(tmp_path: Path, old: str, new: str) -> Path:
    text = ORU.read_text()
    assert old in text, f"fixture text not found: {old!r}"
    path = tmp_path / "arm.toml"
    path.write_text(text.replace(old, new, 1))
    return path


@pytest.mark.parametrize(
    ("old", "new", "expected"),
    [
        ("a = 0.560", "a = 560", "joints #4.a: out of range: allowed range [-30, 30] m (got 560)"),
        ('convention = "modified"', 'convention = "sideways"', "arm.convention"),
        ("d = 0.17885", "d = 0.17885\nlenght = 2", "joints #2.lenght: unknown key"),
        ("d = -0.174", 'd = "long"', "joints #4.d: Input should be a valid number"),
        ("home = 1.5707963267948966", "home = 6.0", "joints #2: home (6.0) must lie within limits"),
        ("velocity = 0.17453292519943295", "velocity = -1", "joints #1.limits.velocity: out of range: allowed range (0, 10] rad/s"),
        ('name = "elbow_pitch"', 'name = "shoulder_yaw"', "joint names must be unique; repeated: shoulder_yaw"),
    ],
)
def test_bad_arm_file_names_file_key_and_allowed_range(tmp_path, old, new, expected):
    path = write_variant(tmp_path, old, new)
    with pytest.raises(ConfigError) as info:
        load_arm_config(path)
    assert str(path) in str(info.value)
    assert expected in str(info.value)


def test_lower_limit_above_upper_is_rejected(tmp_path):
    path = write_variant(tmp_path, "lower = -3.0543261909900767, upper = 3.0543261909900767",
                         "lower = 3.0, upper = -3.0")
    with pytest.raises(ConfigError, match=r"joints #1\.limits: lower \(3.0\) must be less than upper"):
        load_arm_config(path)


def test_unreadable_files_give_clear_errors(tmp_path):
    with pytest.raises(ConfigError, match="file not found"):
        load_arm_config(tmp_path / "missing.toml")
    broken = tmp_path / "broken.toml"
    broken.write_text("x = [")
    with pytest.raises(ConfigError, match="TOML syntax error"):
        load_arm_config(broken)
    binary = tmp_path / "binary.toml"
    binary.write_bytes(b"\xff\xfe\x00")
    with pytest.raises(ConfigError, match="not UTF-8"):
        load_arm_config(binary)


def test_cli_reports_bad_file_in_one_line_without_traceback(tmp_path):
    path = write_variant(tmp_path, "a = 0.560", "a = 560")
    result = subprocess.run([sys.executable, "-m", "spacearm.console.main", "config", "check", str(path)],
                            capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert result.returncode == 2
    assert "Traceback" not in result.stderr
    assert result.stderr.strip() == f"error[bad_config]: {path}: joints #4.a: out of range: allowed range [-30, 30] m (got 560)"
