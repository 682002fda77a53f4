"""The arm file's drive limits reach the drives' configuration (607Dh, 607Fh, 6072h)."""
from __future__ import annotations

import math

import pytest

from spacearm.base.config.arm import load_arm_config
from spacearm.base.config.bus import DEFAULT_BUS_CONFIG, load_bus_config
from spacearm.controller.daemon.hardware import DRIVE_LIMIT_MARGIN, with_drive_limits


def test_the_arm_files_drive_limits_configure_each_drive():
    arm = load_arm_config("configs/arm/ur10.toml")
    bus = load_bus_config("configs/bus/ur10.toml")
    q_min = [j.limits.lower for j in arm.joints]
    q_max = [j.limits.upper for j in arm.joints]
    drives = [j.drive for j in arm.joints]
    configured = with_drive_limits(bus, q_min, q_max, drives)
    joints = [n.joint for n in configured.nodes if n.device == "joint_drive"]
    assert len(joints) == len(arm.joints)
    for settings, joint in zip(joints, arm.joints):
        assert settings.lower == pytest.approx(joint.limits.lower - DRIVE_LIMIT_MARGIN)
        assert settings.max_velocity == pytest.approx(min(joint.drive.velocity, 10.0))
        assert settings.profile_velocity <= settings.max_velocity
        assert settings.max_torque * settings.rated_joint_torque == pytest.approx(joint.drive.torque)


def test_the_test_bed_keeps_its_drive_settings():
    arm = load_arm_config("configs/arm/oru_testbed_6dof.toml")
    bus = load_bus_config(DEFAULT_BUS_CONFIG)
    configured = with_drive_limits(bus, [-math.pi] * 6, [math.pi] * 6, [j.drive for j in arm.joints])
    before = [n.joint for n in bus.nodes if n.device == "joint_drive"]
    after = [n.joint for n in configured.nodes if n.device == "joint_drive"]
    for b, a in zip(before, after):
        assert (a.max_velocity, a.max_torque) == pytest.approx(((b or a).max_velocity, (b or a).max_torque))


def test_a_stated_following_error_window_configures_6065h(tmp_path):
    text = open("configs/arm/ur10.toml").read().replace("[joints.drive]\n", "[joints.drive]\nfollowing_error = 0.03\n", 1)
    path = tmp_path / "ur10_window.toml"
    path.write_text(text)
    arm = load_arm_config(path)
    bus = load_bus_config("configs/bus/ur10.toml")
    configured = with_drive_limits(bus, [j.limits.lower for j in arm.joints], [j.limits.upper for j in arm.joints],
                                   [j.drive for j in arm.joints])
    windows = [n.joint.following_error_window for n in configured.nodes if n.device == "joint_drive"]
    stock = [n.joint.following_error_window for n in bus.nodes if n.device == "joint_drive"]
    assert windows[0] == pytest.approx(0.03)          # stated for joint 1 only
    assert windows[1:] == pytest.approx(stock[1:])    # the others keep the bus file's 6065h
