"""A bus description for an arm of any number of joints: one CiA 402 drive per joint.

The template bus file (configs/bus/arm.toml by default) gives the bus settings and the other
devices (end-effector, F/T sensor); its joint drives are replaced by `n` drives named
joint_1..joint_n with node IDs 1..n, each with the drive limits of its arm joint. Node IDs of
the other devices (16, 17) leave room for 15 joints.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from spacearm.base.config.bus import DEFAULT_BUS_CONFIG, BusConfig, JointSettings, NodeConfig, load_bus_config

MAX_BUS_VELOCITY = 10.0   # rad/s, the 607Fh field's range in JointSettings


@dataclass(frozen=True)
class DriveSpec:
    """One joint's drive as the arm file gives it (SI: rad or m, rad/s or m/s, N m or N)."""
    lower: float
    upper: float
    velocity: float
    torque: float
    following_error: float


def bus_for_arm(drives: list[DriveSpec], template: str | Path = DEFAULT_BUS_CONFIG) -> BusConfig:
    """The template bus with its joint drives replaced by one drive per entry of `drives`."""
    base = load_bus_config(template)
    others = [node for node in base.nodes if node.device != "joint_drive"]
    used = {node.node_id for node in others}
    if len(drives) > min(used, default=128) - 1:
        raise ValueError(f"{len(drives)} joints do not fit below node ID {min(used)} of the template's "
                         "other devices")
    settings = base.joints[0].joint if base.joints else JointSettings()
    joints = []
    for i, drive in enumerate(drives):
        # 6072h max torque is a fraction (<= 3) of the motor's rated torque: rate the motor
        # for the joint's drive torque through the gear.
        rated = drive.torque / settings.gear_ratio
        profile = min(settings.profile_velocity, drive.velocity)
        joint = settings.model_copy(update={
            "lower": drive.lower - 0.05, "upper": drive.upper + 0.05,
            "max_velocity": min(drive.velocity, MAX_BUS_VELOCITY), "profile_velocity": profile,
            "rated_torque": rated, "max_torque": 1.0, "following_error_window": drive.following_error})
        joints.append(NodeConfig(name=f"joint_{i + 1}", node_id=i + 1, device="joint_drive",
                                 heartbeat_period=base.joints[0].heartbeat_period if base.joints else 0.1,
                                 joint=JointSettings.model_validate(joint.model_dump())))
    return BusConfig(bus=base.bus, nodes=joints + others)
