"""Plain values crossing the control cycle: what was measured, what is commanded.

The hardware interface turns CANopen traffic into a `Measurement` each cycle and a
`JointCommand` back into RPDOs; everything between works on these values only.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass(frozen=True)
class DeviceEvent:
    """Something a node reported or failed to report (heartbeat loss, EMCY, boot-up)."""
    node: str
    kind: str        # "heartbeat_lost" | "emcy" | "bootup" | "fault"
    detail: str = ""


@dataclass(frozen=True)
class Measurement:
    time: float                  # s, controller time of this cycle
    sync_counter: int
    q: np.ndarray                # rad
    dq: np.ndarray               # rad/s
    tau: np.ndarray              # N m
    joints_enabled: np.ndarray   # bool per joint: drive in "operation enabled"
    joints_faulted: np.ndarray   # bool per joint
    wrench: np.ndarray           # N, N m: fx fy fz tx ty tz (sensor frame)
    wrench_overload: bool = False
    end_effector: str = "unknown"
    events: tuple[DeviceEvent, ...] = ()
    missing: tuple[str, ...] = ()   # nodes whose PDOs did not arrive this cycle


@dataclass(frozen=True)
class JointCommand:
    q: np.ndarray                # rad, CSP target
    dq: np.ndarray = field(default_factory=lambda: np.zeros(0))  # rad/s feed-forward
    enable: bool = True          # False: drives to quick stop and brakes
    end_effector: Any = None     # spacearm.base.canopen.od.EeCommand to send this cycle, or None
